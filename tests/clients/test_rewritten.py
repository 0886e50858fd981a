"""PTMs rewritten by other tools keep loading in ptm (issue #12 item 7): OpenImageIO as a
texture pipeline does it (`oiiotool`: tiled, PIZ, half floats, one level, a resize; `maketx`
with its own MIP chain; both from the PyPI openimageio wheel), and Python OpenEXR reading and writing a file back. Each rewrite of a
single-file PTM and of the renderer layout's parts is loaded by ptm (fit/examples/ptm_eval.rs)
and its K compared with the original's: equal to 1e-6 for lossless rewrites, within the bound
that half rounding of the coefficients implies for half, and in [0, 1] at the new size for a
resize (whose filter rings coverage a little past 1: it reads clamped).

    python test_rewritten.py PTM_BIN PTM_EVAL WORKDIR
"""
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import OpenEXR

PTM, EVAL, WORK = sys.argv[1:4]
os.makedirs(WORK, exist_ok=True)
DIRS = [(0.0, 0.0, 1.0), (0.5, 0.3, 0.6), (-0.7, 0.2, 0.3), (0.1, -0.95, 0.12)]
failures = []


def check(cond, what):
    print(f"rewritten: {'ok  ' if cond else 'FAIL'} {what}")
    if not cond:
        failures.append(what)


def ptm(*args):
    subprocess.run([PTM, *args], check=True, capture_output=True, cwd=WORK)


def k_of(path):
    """K of every texel for DIRS as ptm evaluates it, or the loader's error."""
    r = subprocess.run([EVAL, path] + [",".join(map(str, d)) for d in DIRS], capture_output=True, text=True)
    if r.returncode != 0:
        return None, r.stderr.strip()
    return np.array(json.loads(r.stdout)), ""


BIN = os.path.dirname(sys.executable)  # the venv's oiiotool and maketx (PyPI openimageio)


def tool(name, *args):
    r = subprocess.run([os.path.join(BIN, name), *args], capture_output=True, text=True)
    check(r.returncode == 0, f"{name} {' '.join(os.path.basename(a) for a in args)} {r.stderr.strip()}")


def oiio_rewrite(src, dst, *args):
    tool("oiiotool", src, *args, "-o", dst)


def maketx(src, dst):
    tool("maketx", src, "--wrap", "periodic", "--tile", "32", "32", "-o", dst)


def python_rewrite(src, dst):
    with OpenEXR.File(src, separate_channels=True) as f:
        # Level 0 only, so the source's tiling, MIP mode and chunk count do not apply.
        header = {k: v for k, v in f.header().items() if k not in ("chunkCount", "tiles", "type")}
        channels = {n: c.pixels.copy() for n, c in f.channels().items()}
    OpenEXR.File(header, channels).write(dst)


def compare(label, path, ref, tol, size=None):
    k, err = k_of(path)
    check(k is not None, f"{label}: ptm loads it {err}")
    if k is None:
        return
    if size:
        check(k.shape[1:] == (size[1], size[0]) and np.all((k >= 0) & (k <= 1)),
              f"{label}: {k.shape[2]}x{k.shape[1]} texels, K in [0, 1]")
        return
    d = float(np.abs(k - ref).max())
    check(d <= tol, f"{label}: K as the original's (max |dK| {d:.1e} <= {tol:.1e})")


ptm("bake", "--res", "32", "--dirs", "24", "--spp", "2", "-o", "s.exr")
for basis, link in [("ptm6", "identity"), ("ptm11", "logistic")]:
    stem = f"{basis}-{link}"
    single = os.path.join(WORK, f"{stem}.ptm.exr")
    ptm("fit", "s.exr", "--basis", basis, "--link", link, "-o", single)
    ref, _ = k_of(single)
    # Half floats move K by at most sum_i |c_i - half(c_i)| (every term is at most 1 on the unit
    # disk), times 1/4 under the logistic link (sigma' <= 1/4): the bound, from the coefficients.
    with OpenEXR.File(single, separate_channels=True) as f:
        c = np.stack([np.asarray(ch.pixels, np.float32) for n, ch in f.channels().items() if n.startswith("ptm.")])
    half_tol = float(np.abs(c - c.astype(np.float16).astype(np.float32)).sum(axis=0).max())
    half_tol = half_tol * (0.25 if link == "logistic" else 1.0) + 1e-6
    for i, (label, args, tol) in enumerate([
            ("tiled 32x32 + PIZ", ["--tile", "32", "32", "--compression", "piz"], 1e-6),
            ("one level, scanline, half, PIZ", ["--selectmip", "0", "--scanline", "-d", "half", "--compression", "piz"], half_tol),
            ("tiled 16x16 + half + ZIPS", ["--tile", "16", "16", "-d", "half", "--compression", "zips"], half_tol),
            ("one level (MIP chain dropped), scanline", ["--selectmip", "0", "--scanline"], 1e-6)]):
        dst = os.path.join(WORK, f"{stem}.oiio{i}.ptm.exr")
        oiio_rewrite(single, dst, *args)
        compare(f"{stem} oiiotool {label}", dst, ref, tol)
    dst = os.path.join(WORK, f"{stem}.tx.ptm.exr")
    maketx(single, dst)
    compare(f"{stem} maketx (its own MIP chain)", dst, ref, 1e-6)
    dst = os.path.join(WORK, f"{stem}.small.ptm.exr")
    oiio_rewrite(single, dst, "--resize", "16x8")
    compare(f"{stem} resized to 16x8", dst, ref, 0, size=(16, 8))
    dst = os.path.join(WORK, f"{stem}.py.ptm.exr")
    python_rewrite(single, dst)
    compare(f"{stem} Python OpenEXR read and written back", dst, ref, 1e-6)

    # The renderer layout: every part rewritten the same way, under the same names.
    rgba = os.path.join(WORK, f"{stem}.rgba")
    os.makedirs(rgba, exist_ok=True)
    ptm("fit", "s.exr", "--basis", basis, "--link", link, "--layout", "rgba", "-o", f"{stem}.rgba/w.ptm.exr")
    parts = sorted(p for p in os.listdir(rgba) if p.endswith(".exr"))
    for how in ["piz-half", "maketx", "python", "resized"]:
        out = os.path.join(WORK, f"{stem}.rgba-{how}")
        os.makedirs(out, exist_ok=True)
        for p in parts:
            src, dst = os.path.join(rgba, p), os.path.join(out, p)
            if how == "piz-half":
                oiio_rewrite(src, dst, "-d", "half", "--compression", "piz", "--tile", "32", "32")
            elif how == "maketx":
                maketx(src, dst)
            elif how == "resized":
                oiio_rewrite(src, dst, "--resize", "16x8")
            else:
                python_rewrite(src, dst)
        compare(f"{stem} renderer layout, parts rewritten ({how})", os.path.join(out, "w.ptm.c0.exr"), ref,
                half_tol if how == "piz-half" else 1e-6, size=(16, 8) if how == "resized" else None)

if failures:
    sys.exit(f"rewritten: {len(failures)} failure(s): " + "; ".join(failures))
print("rewritten: every rewrite loads, with the original's K")
