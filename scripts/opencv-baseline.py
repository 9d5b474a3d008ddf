#!/usr/bin/env python3
"""OpenCV's HoughCircles on the same frames as `impactcam bench analysis --opencv PYTHON`.

Usage: opencv-baseline.py PATH MIN_RADIUS_PX MAX_RADIUS_PX
PATH is a session directory (frames.bin, session.json) or a multi-page 8-bit greyscale TIFF.
Prints one JSON line: {"frames": n, "cpu_s": CPU seconds of HoughCircles over all frames on one
thread, "circles": circles found}. Frames are decoded before the clock starts. The parameters
are OpenCV's usual ones for small bright discs, not tuned to any look.
"""
import json
import sys
import time

import cv2
import numpy as np


def frames_of(path):
    if path.endswith((".tif", ".tiff")):
        ok, pages = cv2.imreadmulti(path, flags=cv2.IMREAD_UNCHANGED)
        if not ok:
            sys.exit(f"{path}: cannot read as a TIFF stack")
        return [p if p.dtype == np.uint8 else (p >> 8).astype(np.uint8) for p in pages]
    with open(f"{path}/session.json") as f:
        cam = json.load(f)["camera"]
    w, h = cam["width"], cam["height"]
    if cam["pixel_format"] != "Mono8":
        sys.exit(f"{path}: only Mono8 sessions, got {cam['pixel_format']}")
    raw = np.fromfile(f"{path}/frames.bin", dtype=np.uint8)[32:]
    n = len(raw) // (w * h)
    return [raw[k * w * h:(k + 1) * w * h].reshape(h, w) for k in range(n)]


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    path, r_min, r_max = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    cv2.setNumThreads(1)
    frames = frames_of(path)
    found = 0
    t0 = time.process_time()
    for img in frames:
        c = cv2.HoughCircles(
            img,
            cv2.HOUGH_GRADIENT,
            dp=1,
            minDist=max(r_min, 1.0),
            param1=100,
            param2=10,
            minRadius=int(r_min),
            maxRadius=int(np.ceil(r_max)),
        )
        found += 0 if c is None else c.shape[1]
    cpu = time.process_time() - t0
    print(json.dumps({"frames": len(frames), "cpu_s": cpu, "circles": found}))


if __name__ == "__main__":
    main()
