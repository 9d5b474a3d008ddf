"""Independent readers and writers from PyPI against impactcam's files (tests/footage_pypi.rs).

  write DIR  pyMRAW writes 8- and 16-bit MRAW + CIH, motmot's FlyMovieFormat writes an FMF;
             the frames also as raw bytes (py8.raw, py16.raw: uint16 little-endian) and the
             FMF's times (py_fmf_times.txt), for impactcam to compare with what it reads.
  check DIR  reads what impactcam wrote there: its MRAW export with pyMRAW, its FMF export with
             motmot, its TIFF export with tifffile (pixels and ImageJ metadata), its cines with
             pycine (16-bit) and AMETEK's cinereader (8- and 16-bit, pixels and times), each
             compared with the frames impactcam wrote beside them as raw bytes.

Exits non-zero, naming the file, on the first difference.
"""

import json
import sys
from pathlib import Path

import numpy as np

W, H, N = 40, 24, 5


def frames(dtype, top):
    rng = np.random.default_rng(20261202)
    return rng.integers(0, top, size=(N, H, W), dtype=np.int64).astype(dtype)


def write(d: Path):
    import pyMRAW
    from motmot.FlyMovieFormat import FlyMovieFormat as fmf

    f8 = frames(np.uint8, 256)
    pyMRAW.save_mraw(f8, str(d / "py8.cih"), bit_depth=8, ext="mraw", info_dict={"Record Rate(fps)": 2000})
    f8.tofile(d / "py8.raw")
    # pyMRAW marks 16-bit files as 12 significant bits: values stay below 4096.
    f16 = frames(np.uint16, 4096)
    pyMRAW.save_mraw(f16, str(d / "py16.cih"), bit_depth=16, ext="mraw", info_dict={"Record Rate(fps)": 2000})
    f16.astype("<u2").tofile(d / "py16.raw")
    times = [1.5 + 0.004 * k for k in range(N)]
    saver = fmf.FlyMovieSaver(str(d / "py.fmf"), version=3, format="MONO8", bits_per_pixel=8)
    for k in range(N):
        saver.add_frame(f8[k], timestamp=times[k])
    saver.close()
    (d / "py_fmf_times.txt").write_text("\n".join(repr(t) for t in times))
    print("wrote py8, py16 (MRAW + CIH) and py.fmf")


def fail(what, message):
    print(f"{what}: {message}", file=sys.stderr)
    sys.exit(1)


def check(d: Path):
    import pyMRAW
    import tifffile
    from motmot.FlyMovieFormat import FlyMovieFormat as fmf
    from pycine.raw import read_frames
    import cinereader

    meta = json.loads((d / "meta.json").read_text())
    w, h, n = meta["width"], meta["height"], meta["frames"]
    ref = np.fromfile(d / "session.raw", dtype=np.uint8).reshape(n, h, w)

    images, cih = pyMRAW.load_video(str(d / "ours.cih"))
    if cih["Record Rate(fps)"] != meta["frame_rate_hz"] or cih["Total Frame"] != n:
        fail("ours.cih", f"rate {cih['Record Rate(fps)']} and {cih['Total Frame']} frames, expected {meta['frame_rate_hz']} and {n}")
    if not np.array_equal(np.asarray(images), ref):
        fail("ours.mraw", "pyMRAW reads other pixels")
    print(f"pyMRAW: ours.mraw {n} frames of {w}x{h} equal")

    movie = fmf.FlyMovie(str(d / "ours.fmf"))
    if movie.get_n_frames() != n:
        fail("ours.fmf", f"{movie.get_n_frames()} frames, expected {n}")
    times = np.array(meta["times_s"])
    for k in range(n):
        frame, t = movie.get_frame(k)
        if not np.array_equal(frame, ref[k]):
            fail("ours.fmf", f"frame {k}: motmot reads other pixels")
        if abs(t - times[k]) > 1e-12:
            fail("ours.fmf", f"frame {k}: time {t}, expected {times[k]}")
    print(f"motmot: ours.fmf {n} frames and times equal")

    with tifffile.TiffFile(d / "ours.tif") as tif:
        ij = tif.imagej_metadata
        stack = tif.asarray()
    if not ij:
        fail("ours.tif", "tifffile finds no ImageJ metadata")
    want = {"images": n, "frames": n}
    for key, value in want.items():
        if ij.get(key) != value:
            fail("ours.tif", f"ImageJ {key} = {ij.get(key)}, expected {value}")
    if abs(float(ij.get("finterval", 0)) - 1.0 / meta["frame_rate_hz"]) > 1e-12:
        fail("ours.tif", f"ImageJ finterval = {ij.get('finterval')}, expected {1.0 / meta['frame_rate_hz']}")
    if not np.array_equal(stack.reshape(n, h, w), ref):
        fail("ours.tif", "tifffile reads other pixels")
    print(f"tifffile: ours.tif {n} pages equal, ImageJ images/frames/finterval as expected")

    # Cines from impactcam's writer: 8-bit (the session's frames) and 16-bit with 12 bits.
    c8 = d / "ours8.cine"
    md = cinereader.read_metadata(str(c8))
    if md.ImageCount != n or md.biWidth != w or md.biHeight != h:
        fail("ours8.cine", f"cinereader: {md.ImageCount} images of {md.biWidth}x{md.biHeight}, expected {n} of {w}x{h}")
    for k in range(n):
        img = cinereader.read_image(md, str(c8), md.FirstImageNo + k)
        if not np.array_equal(img, ref[k]):
            fail("ours8.cine", f"image {k}: cinereader reads other pixels")
    from_trigger_us = cinereader.read_time_from_trigger(md, str(c8))
    want_us = np.array(meta["cine_from_trigger_s"]) * 1e6
    if np.max(np.abs(from_trigger_us - want_us)) > 0.011:
        fail("ours8.cine", f"cinereader's times from the trigger {from_trigger_us[:3]} µs, expected {want_us[:3]}")
    print(f"cinereader: ours8.cine {n} images and their times from the trigger equal")

    c16 = d / "ours16.cine"
    ref16 = np.fromfile(d / "ours16.raw", dtype="<u2").reshape(-1, h, w)
    md = cinereader.read_metadata(str(c16))
    for k in range(len(ref16)):
        img = cinereader.read_image(md, str(c16), md.FirstImageNo + k)
        if not np.array_equal(img, ref16[k]):
            fail("ours16.cine", f"image {k}: cinereader reads other pixels")
    raw, setup, bpp = read_frames(str(c16), start_frame=1, count=len(ref16))
    if bpp != 12 or setup.FrameRate != meta["frame_rate_hz"]:
        fail("ours16.cine", f"pycine: {bpp} bits at {setup.FrameRate} frames/s, expected 12 at {meta['frame_rate_hz']}")
    for k, img in enumerate(raw):
        if not np.array_equal(img, ref16[k]):
            fail("ours16.cine", f"image {k}: pycine reads other pixels")
    print(f"cinereader and pycine: ours16.cine {len(ref16)} 12-bit images equal")


if __name__ == "__main__":
    {"write": write, "check": check}[sys.argv[1]](Path(sys.argv[2]))
