"""Every kind of file ptm writes, opened with the official Python OpenEXR bindings and with
OpenImageIO (PyPI wheels), compared with ptm's own reader: the sample stack, PTMs (float and
half, identity and logistic, with a ring-dome warning, error maps, holes, MIP levels), the
renderer layout's parts, the preview EXR. Coefficients read by Python are evaluated in numpy
and compared with Ptm::eval_dir (fit/examples/ptm_eval.rs) to 1e-6.

    python test_readers.py PTM_BIN PTM_EVAL WORKDIR
"""
import json
import os
import subprocess
import sys

import numpy as np
import OpenEXR
import OpenImageIO as oiio

PTM, EVAL, WORK = sys.argv[1:4]
os.makedirs(WORK, exist_ok=True)
MONO = {"ptm6": ["u2", "u", "uv", "v", "v2", "1"],
        "ptm11": ["u3", "v3", "u2v2", "u2v", "uv2", "u2", "v2", "uv", "u", "v", "1"]}
POW = {"1": (0, 0), "u": (1, 0), "v": (0, 1), "u2": (2, 0), "uv": (1, 1), "v2": (0, 2), "u3": (3, 0),
       "v3": (0, 3), "u2v": (2, 1), "uv2": (1, 2), "u2v2": (2, 2)}
PARTS = {"ptm6": [["u2", "u", "uv"], ["v", "v2", "1", "coverage"]],
         "ptm11": [["u3", "v3", "u2v2", "u2v"], ["uv2", "u2", "v2", "uv"], ["u", "v", "1", "coverage"]]}
DIRS = [(0.0, 0.0, 1.0), (0.5, 0.3, 0.6), (-0.7, 0.2, 0.3)]
failures = []


def ptm(*args):
    subprocess.run([PTM, *args], check=True, capture_output=True, cwd=WORK)


def check(cond, what):
    if not cond:
        failures.append(what)
        print(f"readers: FAIL {what}")


def read_both(path):
    """Channels (level 0) and header by OpenEXR and by OIIO; asserts they agree."""
    f = OpenEXR.File(os.path.join(WORK, path), separate_channels=True)
    chans = {n: np.asarray(c.pixels, dtype=np.float64) for n, c in f.channels().items()}
    header = f.header()
    inp = oiio.ImageInput.open(os.path.join(WORK, path))
    check(inp is not None, f"{path}: OIIO opens it ({oiio.geterror()})")
    spec = inp.spec()
    data = inp.read_image(0, 0, 0, spec.nchannels, "float")
    for i, n in enumerate(spec.channelnames):
        check(np.array_equal(np.asarray(data[:, :, i], dtype=np.float64), chans[n].reshape(spec.height, spec.width)),
              f"{path}: OIIO and OpenEXR agree on channel {n}")
    levels = 1
    while inp.seek_subimage(0, levels):
        levels += 1
    inp.close()
    return chans, header, spec, levels


def k_numpy(coeffs, basis, link, uv, d):
    l = np.array(d) / np.linalg.norm(d)
    pu, pv, pz = l
    if uv == "hemispherical":
        r = np.hypot(pu, pv)
        th = np.arctan2(r, pz)
        s = th / (np.pi / 2) / r if r > 0 else 0.0
        pu, pv = pu * s, pv * s
    p = sum(coeffs[m].astype(np.float32) * np.float32(pu ** POW[m][0] * pv ** POW[m][1]) for m in MONO[basis])
    if link == "logistic":
        p = 1 / (1 + np.exp(-p.astype(np.float64)))
    return np.clip(p, 0, 1)


def compare_eval(path, coeffs, basis, link, uv, w, h):
    ref = np.array(json.loads(subprocess.run([EVAL, os.path.join(WORK, path)] + [",".join(map(str, d)) for d in DIRS],
                                             check=True, capture_output=True, text=True).stdout))
    err = max(np.abs(k_numpy(coeffs, basis, link, uv, d).reshape(h, w) - ref[i]).max() for i, d in enumerate(DIRS))
    check(err <= 1e-6, f"{path}: numpy K from Python-read coefficients = Ptm::eval (max diff {err:.1e})")
    return err


# The bakes: a plain stack, a ring dome (its warnings hold ° and –), a holey swatch.
ptm("bake", "--res", "24", "--spp", "2", "--dirs", "48", "-o", "s.exr")
ptm("bake", "--res", "24", "--spp", "2", "--dome", "rings:50x12,70x6", "-o", "rings.exr")
kinds = [
    ("s.exr", ["fit", "s.exr", "-o", "plain.ptm.exr", "--no-mips"], "plain.ptm.exr"),
    ("s.exr", ["fit", "s.exr", "--basis", "ptm11", "--half", "--error-map", "-o", "half.ptm.exr"], "half.ptm.exr"),
    ("s.exr", ["fit", "s.exr", "--link", "logistic", "--uv", "hemispherical", "-o", "logi.ptm.exr"], "logi.ptm.exr"),
    ("rings.exr", ["fit", "rings.exr", "--error-map", "-o", "warn.ptm.exr"], "warn.ptm.exr"),
]
worst = 0.0
chans, header, spec, _ = read_both("s.exr")
k_names = sorted(n for n in chans if n.startswith("K."))
check(header.get("stack:version") == "ptm-samples/1", "stack: stack:version")
check(len(k_names) == header.get("stack:nLights") == 48, f"stack: {len(k_names)} K channels = stack:nLights")
check(len(header.get("stack:lightDirs", [])) == 48, "stack: 48 light directions")
for _, args, out in kinds:
    try:
        ptm(*args)
        chans, header, spec, levels = read_both(out)
    except Exception as e:  # noqa: BLE001 — report which file fails, keep going
        check(False, f"{out}: opens in Python OpenEXR and OIIO ({type(e).__name__}: {e})")
        continue
    basis = header["ptm:basis"]
    link, uv = header.get("ptm:link", "identity"), header.get("ptm:uv", "projected")
    check(all(f"ptm.{m}" in chans for m in MONO[basis]), f"{out}: every ptm.<monomial> channel")
    check(spec.get_string_attribute("ptm:basis") == basis, f"{out}: OIIO sees ptm:basis")
    half = "half" in out
    check((spec.format == oiio.HALF) == half, f"{out}: stored type is {'half' if half else 'float'}")
    check(("err.rms" in chans) == ("--error-map" in args), f"{out}: err.* maps as asked")
    check((levels > 1) == ("--no-mips" not in args), f"{out}: {levels} MIP levels")
    coeffs = {m: chans[f"ptm.{m}"] for m in MONO[basis]}
    worst = max(worst, compare_eval(out, coeffs, basis, link, uv, spec.width, spec.height))
    # The renderer layout of the same PTM: RGB(A) parts with the same coefficients.
    rg = out.replace(".ptm.exr", ".rgba.ptm.exr")
    ptm("convert", out, "-o", rg)
    for k, slots in enumerate(PARTS[basis]):
        part = rg.replace(".exr", f".c{k}.exr")
        pc, ph, ps, plevels = read_both(part)
        check(ph.get("ptm:layout") == "rgba/1" and ph.get("ptm:part") == k, f"{part}: ptm:layout, ptm:part")
        check(ps.get_string_attribute("wrapmodes") == "periodic,periodic", f"{part}: OIIO wrapmodes periodic")
        check(plevels == levels, f"{part}: {plevels} MIP levels like the PTM's {levels}")
        for i, m in enumerate(slots):
            want = chans.get(f"ptm.{m}" if m != "coverage" else "coverage", np.ones(spec.width * spec.height))
            check(np.array_equal(pc["RGBA"[i]], want), f"{part}: {'RGBA'[i]} = {m}")
    worst = max(worst, compare_eval(rg.replace(".exr", ".c0.exr"), coeffs, basis, link, uv, spec.width, spec.height))
    if out == "warn.ptm.exr":
        check(any("°" in w for w in header.get("ptm:warnings", [])), f"{out}: warnings read back as UTF-8 text")
# The Python example of docs/pipeline.md, run as written on a renderer-layout PTM named w.ptm.
readme = open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "docs", "pipeline.md")).read()
block = readme.split("<!-- readme-python -->\n```python\n", 1)[1].split("```", 1)[0]
ptm("convert", "half.ptm.exr", "-o", "w.ptm.exr", "--layout", "rgba")
cwd = os.getcwd()
os.chdir(WORK)
scope = {}
exec(compile(block, "docs/pipeline.md (Python example)", "exec"), scope)
os.chdir(cwd)
check(scope["r"].size == 24 * 24, "README Python example reads a coefficient plane")
try:
    ptm("preview", "--ptm", "plain.ptm.exr", "--size", "32,32", "-o", "pv.png", "--exr", "pv.exr")
    pc, ph, ps, _ = read_both("pv.exr")
    check(ps.nchannels >= 3, "preview EXR: colour channels")
except subprocess.CalledProcessError as e:
    check(False, f"preview EXR written ({e.stderr.decode()[-200:]})")
print(f"readers: {len(kinds)} PTMs, their rgba layouts, the stack and the preview EXR opened in OpenEXR "
      f"{OpenEXR.__version__} and OIIO {oiio.VERSION_STRING}; numpy K vs Ptm::eval max diff {worst:.1e}")
if failures:
    print(f"readers: {len(failures)} failed")
    sys.exit(1)
