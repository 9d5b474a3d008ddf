#!/usr/bin/env python3
"""Draws a recording of the lab's validation set again under another look, with a renderer of
its own: a check of the analysis on footage neither hw-sim nor the validation set's renderer
draws (docs/accuracy.md, session 51). It shares no code or constant with hw-sim or the
analysis; it reads only the recording's `truth.json` (every frame's centres, rotations, spins
and the markers' places on the spheres) and `calibration.json` (the views' exact maps), and
writes a folder that `impactcam bench validation` reads (frames.tif, and the calibration,
truth and centres copied).

Usage: rerender-looks.py SESSION_DIR OUT_DIR LOOK_JSON
  e.g. rerender-looks.py ../shared/validation/v03 grey/v03 '{"seed": 2, "background_dn": 80,
       "light_off_axis_deg": [30, 30]}'
Needs numpy and tifffile (python3 -m venv v && v/bin/pip install numpy tifffile).

The look's keys (all optional): seed; background_dn (20); albedo_dn (190); ambient (0.35);
light_off_axis_deg [direct, mirror] ([20, 20]; the azimuth is drawn from the seed);
illum (0.12: the illumination field's gradient and vignetting, drawn up to this);
specular_dn (0) and shininess (60): a Blinn-Phong highlight, clipped at 255 like the rest;
gamma (1: the camera's encoding, not told to the analysis); marker_factor (0.2: the paint keeps
this of the shading); blotchy_markers (false: each marker three overlapping caps) and
marker_scale (1); texture (0: the albedo varies by this in low waves fixed on the sphere);
shadow {distance_mm, darkness, soft_px}: each sphere's shadow cast along the lamp onto a
backdrop that far behind; ghost {fraction, offset_px}: a second-surface mirror's faint copy in
the mirror view; dust (0: sensor dust blobs); exposure_s (the recording's: smear over it, and
the calibration says so); read_noise_dn (2), shot_dn_per_e (0.1), column_fpn_dn (0);
scale (1: the camera's resolution times this, the same rig: frames, maps, regions and true
centres scaled about the pixels' edges, so the spheres span that many times the pixels);
perspective_mm (none: orthographic as the recording's maps; a number, or [direct, mirror]):
each view seen through a pinhole that far from the middle of the spheres' path, its
magnification there the recording's map; the 3×4 projections (world metres to homogeneous
px) go into calibration.json as each view's "P", A and b stay the affine map at that middle,
and centres.csv holds the images of the spheres' centres through the pinholes.
"""
import json, sys, os, shutil, math
import numpy as np
import tifffile

src, dst, look_json = sys.argv[1], sys.argv[2], sys.argv[3]
look = json.loads(look_json)
rng = np.random.default_rng(look.get("seed", 1))
truth = json.load(open(os.path.join(src, "truth.json")))
cal = json.load(open(os.path.join(src, "calibration.json")))
C = cal["calibration"]
scale = look.get("scale", 1)
if scale != 1:
    # A finer sensor on the same rig: pixel k spans [k - 1/2, k + 1/2], so a point at u is at
    # scale·(u + 1/2) - 1/2 on it.
    if int(scale) != scale or scale < 1:
        sys.exit("scale must be a whole number >= 1")
    scale = int(scale)
    cal = json.loads(json.dumps(cal))
    C = cal["calibration"]
    C["image_width"] *= scale
    C["image_height"] *= scale
    for name in ("direct", "mirror"):
        c = C[name]
        c["A"] = [[a * scale for a in row] for row in c["A"]]
        c["b"] = [scale * (x + 0.5) - 0.5 for x in c["b"]]
        c["rows"] = [r * scale for r in c["rows"]]
        if "pixels_per_metre" in c:
            c["pixels_per_metre"] *= scale
        if "origin_px" in c:
            c["origin_px"] = [scale * (x + 0.5) - 0.5 for x in c["origin_px"]]
W, H = C["image_width"], C["image_height"]
fps = cal["fps"]
exposure = look.get("exposure_s", cal["exposure_s"])
ss = 4
rad = {"a": cal["diameter_a_m"] / 2, "b": cal["diameter_b_m"] / 2}

def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)

persp = look.get("perspective_mm", None)
if persp is not None and not isinstance(persp, list):
    persp = [persp, persp]
# The middle of the spheres' path (the pinholes' reference point), m.
c0 = np.mean([fr["spheres"][k]["centre_m"] for fr in truth["frames"] for k in ("a", "b")], axis=0)
views = {}
for name in ("direct", "mirror"):
    c = C[name]
    A = np.array(c["A"], float)
    b = np.array(c["b"], float)
    nvec = unit(np.cross(A[0], A[1]))
    if nvec @ np.array(c["view_direction_to_camera"]) < 0:
        nvec = -nvec
    Apinv = A.T @ np.linalg.inv(A @ A.T)
    r0, r1 = c["rows"]
    # Light: off-axis angle and azimuth drawn, in the plane of the view.
    off = math.radians(look.get("light_off_axis_deg", [20, 20])[0 if name == "direct" else 1])
    az = rng.uniform(0, 2 * math.pi)
    eu, ev = unit(A[0]), unit(A[1])
    L = unit(math.cos(off) * nvec + math.sin(off) * (math.cos(az) * eu - math.sin(az) * ev))
    g = look.get("illum", 0.12)
    field = [rng.uniform(-g, g), rng.uniform(-g, g), -rng.uniform(0, g)]
    gain = 1.0 if name == "direct" else rng.uniform(0.85, 0.92)
    views[name] = dict(A=A, b=b, n=nvec, Apinv=Apinv, rows=(r0, r1), L=L, field=field, gain=gain)
    if persp is not None:
        # A pinhole on the view's axis, D from c0: u = u0 + A·(X − c0)/w with w = 1 − n·(X − c0)/D,
        # the same magnification as A at c0's depth. As a 3×4 matrix on [X, 1] (metres).
        D = persp[0 if name == "direct" else 1] / 1000
        u0 = A @ c0 + b
        P = np.zeros((3, 4))
        P[2, :3] = -nvec / D
        P[2, 3] = 1 + nvec @ c0 / D
        P[:2, :3] = A - np.outer(u0, nvec) / D
        P[:2, 3] = -A @ c0 + u0 * P[2, 3]
        views[name].update(P=P, D=D, u0=u0, cam=c0 + D * nvec)
        c["P"] = P.tolist()

def project(vw, X):
    """The image of world point X (m) and the px per m there (the magnification)."""
    if "P" in vw:
        h = vw["P"] @ np.append(X, 1.0)
        return h[:2] / h[2], np.linalg.norm(vw["A"][0]) / h[2]
    return vw["A"] @ X + vw["b"], np.linalg.norm(vw["A"][0])

bg_dn = look.get("background_dn", 20.0)
albedo = look.get("albedo_dn", 190.0)
ambient = look.get("ambient", 0.35)
spec = look.get("specular_dn", 0.0)
shin = look.get("shininess", 60.0)
gamma = look.get("gamma", 1.0)
marker_factor = look.get("marker_factor", 0.2)
blotchy = look.get("blotchy_markers", False)
marker_scale = look.get("marker_scale", 1.0)
ang_r = truth["render"]["marker_angular_radius_rad"] * marker_scale
markers = {k: np.array(v, float) for k, v in truth["render"]["markers_body"].items()}
sub_markers = {}
for k, m in markers.items():
    subs = []
    for mi in m:
        if blotchy:
            # Three overlapping caps of different sizes, a little apart: a hand-painted blob.
            t1 = unit(np.cross(mi, [0.3, 0.5, 0.8]))
            t2 = np.cross(mi, t1)
            for _ in range(3):
                d = rng.normal(0, 0.45 * ang_r, 2)
                subs.append((unit(mi + d[0] * t1 + d[1] * t2), ang_r * rng.uniform(0.55, 0.85)))
        else:
            subs.append((mi, ang_r))
    sub_markers[k] = subs
# Albedo texture fixed in the body: a few low-order waves.
tex_amp = look.get("texture", 0.0)
tex_waves = [(unit(rng.normal(size=3)), rng.uniform(2, 6), rng.uniform(0, 6.28)) for _ in range(4)]
# Shadow on a backdrop behind each view's spheres.
shadow = look.get("shadow", None)  # dict(distance_mm, darkness, soft_px)
ghost = look.get("ghost", None)  # dict(fraction, offset_px)  (mirror only)
dust = look.get("dust", 0)  # number of sensor dust blobs
dust_blobs = [(rng.uniform(20, W - 20), rng.uniform(10, H - 10), rng.uniform(1.0, 2.5), rng.uniform(0.75, 0.9)) for _ in range(dust)]
read_sigma = look.get("read_noise_dn", 2.0)
shot = look.get("shot_dn_per_e", 0.1)
col_fpn = look.get("column_fpn_dn", 0.0)
col_offsets = rng.normal(0, col_fpn, W) if col_fpn > 0 else np.zeros(W)

offs = (np.arange(ss) + 0.5) / ss - 0.5

def rot(omega, dt):
    th = np.linalg.norm(omega) * dt
    if th < 1e-12:
        return np.eye(3)
    k = omega / np.linalg.norm(omega)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K

def render_view(vw, states):
    r0, r1 = vw["rows"]
    vv = np.arange(r0, r1)[:, None] + offs[None, :]
    uu = np.arange(W)[:, None] + offs[None, :]
    V = np.repeat(vv.reshape(-1), W * ss).reshape(-1, W * ss)
    U = np.tile(uu.reshape(-1), ((r1 - r0) * ss, 1))
    img = np.full(U.shape, bg_dn)
    # Illumination field
    x = (U - W / 2) / W
    y = (V - (r0 + r1) / 2) / ((r1 - r0) / 2) / 2
    fx, fy, fq = vw["field"]
    G = 1 + fx * x + fy * y + fq * (x * x + y * y)
    depth = np.full(U.shape, -np.inf)
    n = vw["n"]
    if shadow:
        for name, (c, R) in states.items():
            D = shadow["distance_mm"] / 1000
            L = vw["L"]
            t = (c @ n + D) / (L @ n)
            s = c - L * t
            sc, mag = project(vw, s)
            rpx = rad[name] * mag
            d = np.hypot(U - sc[0], V - sc[1])
            f = 1 / (1 + np.exp((d - rpx) / shadow["soft_px"]))
            img = img * (1 - shadow["darkness"] * f)
    for name, (c, R) in states.items():
        r = rad[name]
        ci, mag = project(vw, c)
        rpx = r * mag
        box = (np.abs(U - ci[0]) < 1.05 * rpx + 2) & (np.abs(V - ci[1]) < 1.05 * rpx + 2)
        if not box.any():
            continue
        if "P" in vw:
            # Each sample's ray from the pinhole through its point on the plane through c0.
            Q = c0[:, None] + vw["Apinv"] @ np.stack([U[box] - vw["u0"][0], V[box] - vw["u0"][1]])
            d = Q - vw["cam"][:, None]
            oc = (vw["cam"] - c)[:, None]
            bq = (d * oc).sum(0)
            aq = (d * d).sum(0)
            disc = bq * bq - aq * ((oc * oc).sum() - r * r)
            inside = disc > 0
            t = (-bq - np.sqrt(np.clip(disc, 0, None))) / aq
            P = vw["cam"][:, None] + t[None, :] * d - c[:, None]
            N = P / r
            dep = -t
        else:
            du = U[box] - ci[0]
            dv = V[box] - ci[1]
            X = (vw["Apinv"] @ np.stack([du, dv]))  # 3 x N world offsets in the image plane
            rho2 = (X * X).sum(0) / (r * r)
            inside = rho2 < 1
            h = np.sqrt(np.clip(1 - rho2, 0, None)) * r
            P = X + h[None, :] * n[:, None]
            N = P / r
            dep = (c @ n) + (P.T @ n)
        idx = np.flatnonzero(box)
        sel = inside & (dep > depth.reshape(-1)[idx])
        if not sel.any():
            continue
        Ns = N[:, sel]
        L = vw["L"]
        lam = np.clip(L @ Ns, 0, None)
        nb = R.T @ Ns
        a = albedo * np.ones(Ns.shape[1])
        if tex_amp:
            t = np.zeros(Ns.shape[1])
            for (k, f, ph) in tex_waves:
                t += np.sin(f * (k @ nb) + ph)
            a = a * (1 + tex_amp * t / 2)
        val = a * (ambient + (1 - ambient) * lam)
        for (m, ar) in sub_markers[name]:
            on = (m @ nb) > math.cos(ar)
            val = np.where(on, val * marker_factor, val)
        if spec:
            Hh = unit(L + n)
            val = val + spec * np.clip(Hh @ Ns, 0, None) ** shin
        flat = img.reshape(-1)
        flat[idx[sel]] = val
        d = depth.reshape(-1)
        d[idx[sel]] = dep[sel]
    img = img * G * vw["gain"]
    # Average the supersamples.
    img = img.reshape(r1 - r0, ss, W, ss).mean(axis=(1, 3))
    return img

frames = truth["frames"]
nsub = max(1, int(round(exposure / 0.0001)) * 2) if exposure > 0.00015 else 2
out = np.zeros((len(frames), H, W), np.uint8)
for k, fr in enumerate(frames):
    lin = np.zeros((H, W))
    for j in range(nsub):
        tau = (j + 0.5) / nsub * exposure - exposure / 2
        states = {}
        for name in ("a", "b"):
            s = fr["spheres"][name]
            c = np.array(s["centre_m"]) + np.array(s["velocity_mps"]) * tau
            R = rot(np.array(s["spin_radps"]), tau) @ np.array(s["rotation_body_to_world"])
            states[name] = (c, R)
        for vname, vw in views.items():
            r0, r1 = vw["rows"]
            lin[r0:r1] += render_view(vw, states) / nsub
    if ghost:
        vw = views["mirror"]
        r0, r1 = vw["rows"]
        sh = ghost["offset_px"]
        m = lin[r0:r1].copy()
        shifted = np.roll(m, sh, axis=0)
        lin[r0:r1] = m * (1 - ghost["fraction"]) + shifted * ghost["fraction"] * 1.0
    for (du, dv, s, f) in dust_blobs:
        yy, xx = np.mgrid[0:H, 0:W]
        lin *= 1 - (1 - f) * np.exp(-((xx - du) ** 2 + (yy - dv) ** 2) / (2 * s * s))
    lin = np.clip(lin, 0, None)
    noisy = lin + rng.normal(0, 1, lin.shape) * np.sqrt(read_sigma ** 2 + shot * lin)
    noisy += col_offsets[None, :]
    noisy = np.clip(noisy, 0, 255)
    if gamma != 1.0:
        noisy = 255 * (noisy / 255) ** gamma
    out[k] = np.clip(np.round(noisy), 0, 255).astype(np.uint8)

os.makedirs(dst, exist_ok=True)
tifffile.imwrite(os.path.join(dst, "frames.tif"), out, imagej=True, metadata={"finterval": 1 / fps})
cal2 = dict(cal)
cal2["exposure_s"] = exposure
json.dump(cal2, open(os.path.join(dst, "calibration.json"), "w"), indent=1)
shutil.copy(os.path.join(src, "truth.json"), dst)
def centre_cell(fr, h, x):
    """One cell of centres.csv as drawn: through the pinholes, or scaled with the sensor."""
    if h in ("frame", "time_s") or x == "":
        return x
    if persp is not None:
        sph, axis, view = h.split("_")
        uv, _ = project(views[view], np.array(fr["spheres"][sph]["centre_m"]))
        return repr(float(uv[0] if axis == "x" else uv[1]))
    return repr(scale * (float(x) + 0.5) - 0.5)

if persp is None and scale == 1:
    shutil.copy(os.path.join(src, "centres.csv"), dst)
else:
    import csv
    with open(os.path.join(src, "centres.csv")) as f_in, open(os.path.join(dst, "centres.csv"), "w", newline="") as f_out:
        rows = csv.reader(f_in)
        head = next(rows)
        w = csv.writer(f_out)
        w.writerow(head)
        for row in rows:
            fr = frames[int(row[0])]
            w.writerow([centre_cell(fr, h, x) for h, x in zip(head, row)])
