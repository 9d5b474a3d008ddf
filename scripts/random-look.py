#!/usr/bin/env python3
"""Draws a look for scripts/rerender-looks.py at random from an integer seed: every key the
renderer knows, combined (lamps 0-40 deg off each view's axis, a ground 5-110 grey levels under
spheres of 120-235, ambient 0.1-0.5, highlights, gamma, paint, blotchy or large dots, texture,
shadows, a mirror's ghost, dust, column noise, pinholes 250-700 mm away). A check of the
analysis on looks nobody chose (docs/accuracy.md, session 56); no constant of the analysis is
set from them.

Usage: random-look.py SEED   (prints the look's JSON)
  e.g. for v in ../shared/validation/v0?; do
         scripts/rerender-looks.py $v looks/r1/$(basename $v) "$(scripts/random-look.py 1)"; done
       impactcam bench validation looks/r1
"""
import json, random, sys

r = random.Random(int(sys.argv[1]))
look = {"seed": r.randrange(1, 10**6)}
look["background_dn"] = round(r.uniform(5, 110), 1)
look["albedo_dn"] = round(r.uniform(max(look["background_dn"] + 50, 120), 235), 1)
look["ambient"] = round(r.uniform(0.1, 0.5), 2)
look["light_off_axis_deg"] = [round(r.uniform(0, 40), 1), round(r.uniform(0, 40), 1)]
look["illum"] = round(r.uniform(0, 0.25), 3)
if r.random() < 0.4:
    look["specular_dn"] = round(r.uniform(20, 120), 1)
    look["shininess"] = round(r.uniform(20, 200))
if r.random() < 0.3:
    look["gamma"] = round(r.uniform(0.5, 1.6), 2)
look["marker_factor"] = round(r.uniform(0.1, 0.5), 2)
if r.random() < 0.3:
    look["blotchy_markers"] = True
look["marker_scale"] = round(r.uniform(0.7, 1.5), 2)
if r.random() < 0.3:
    look["texture"] = round(r.uniform(0.02, 0.15), 3)
if r.random() < 0.25:
    look["shadow"] = {
        "distance_mm": round(r.uniform(5, 40), 1),
        "darkness": round(r.uniform(0.2, 0.7), 2),
        "soft_px": round(r.uniform(0.5, 3), 2),
    }
if r.random() < 0.2:
    look["ghost"] = {"fraction": round(r.uniform(0.03, 0.12), 3), "offset_px": round(r.uniform(1, 4), 2)}
if r.random() < 0.3:
    look["dust"] = r.randrange(1, 8)
look["read_noise_dn"] = round(r.uniform(1, 3), 2)
if r.random() < 0.2:
    look["column_fpn_dn"] = round(r.uniform(0.3, 2), 2)
if r.random() < 0.3:
    look["perspective_mm"] = round(r.uniform(250, 700))
print(json.dumps(look))
