"""The Python module `ptm` (python/, built by maturin into .deps/py) against the Rust reader on
files the real `ptm` binary makes: Ptm.eval_xy / Ptm.eval_dir equal Ptm::eval / Ptm::eval_dir
(fit/examples/ptm_eval.rs) to 1e-6 for ptm6 and ptm11, both links and both (u, v) maps, over
many lights (grazing, at and below the horizon, outside the unit disk); save/load round trips
(channels and rgba layouts, float and half, coverage, MIP levels, error maps) keep coefficients
and metadata; errors name the file; the README's Python example runs as written.

    python test_python_module.py PTM_BIN PTM_EVAL WORKDIR
"""
import json
import os
import subprocess
import sys
import time

import numpy as np
import OpenEXR

import ptm

PTM, EVAL, WORK = sys.argv[1:4]
os.makedirs(WORK, exist_ok=True)
TOL = 1e-6
POW = {"1": (0, 0), "u": (1, 0), "v": (0, 1), "u2": (2, 0), "uv": (1, 1), "v2": (0, 2), "u3": (3, 0),
       "v3": (0, 3), "u2v": (2, 1), "uv2": (1, 2), "u2v2": (2, 2)}
failures = []


def run(*args):
    subprocess.run([PTM, *args], check=True, capture_output=True, cwd=WORK)


def w(name):
    return os.path.join(WORK, name)


def check(cond, what):
    if not cond:
        failures.append(what)
        print(f"python module: FAIL {what}")


def rust_k(path, args):
    """K of every texel from ptm_eval (Ptm::eval_dir for X,Y,Z; Ptm::eval for U,V)."""
    out = subprocess.run([EVAL, path, *args], check=True, capture_output=True, text=True).stdout
    # `{:e}` prints the shortest decimal that reads back as the same f32: rounding it to f32
    # recovers Rust's value exactly.
    return np.array(json.loads(out), dtype=np.float64).astype(np.float32)


def directions():
    """Unit directions: a Fibonacci sphere (both hemispheres), the zenith and lights a hair off
    it (the hemispherical map's r → 0 branch), grazing ones at l_z = 1e-6 … 1e-2, and exactly
    on the horizon (l_z = 0 and −0)."""
    n = 160
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    phi = i * np.pi * (3 - np.sqrt(5))
    d = [np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)]
    d.append(np.array([[0, 0, 1], [1e-9, 0, 1], [3e-5, -2e-5, 1], [0, 1e-3, 1]], dtype=np.float64))
    for ez in [1e-6, 1e-4, 1e-2]:
        for az in [0.3, 2.0, 4.0]:
            d.append(np.array([[np.cos(az), np.sin(az), ez]]))
    d.append(np.array([[0.6, 0.8, 0.0], [-1.0, 0.0, -0.0], [0.0, 0.0, -1.0]]))
    d = np.concatenate(d)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def uv_pairs():
    """(u, v) as float32: projections of upper-hemisphere lights, the origin, and points on and
    outside the unit disk (the hemispherical map clamps r to 1 there, as Ptm::eval does)."""
    d = directions()
    d = d[d[:, 2] > 0]
    extra = np.array([[0, 0], [1, 0], [0, -1], [0.6, 0.8], [1.2, 0.3], [-0.9, -0.9], [2e-5, 1e-5]])
    return np.concatenate([d[:, :2], extra]).astype(np.float32)


def compare_eval(path, p):
    """Worst |ΔK| of p.eval_dir and p.eval against ptm_eval on `path`."""
    d = directions()
    ref = rust_k(path, [",".join(repr(float(x)) for x in row) for row in d])
    got = p.eval_dir(d)
    check(got.shape == (len(d), p.height, p.width) and got.dtype == np.float32,
          f"{path}: eval_dir of {len(d)} lights has shape (N, height, width), float32")
    err = float(np.abs(got.astype(np.float64) - ref).max())
    one = p.eval_dir(d[5])
    check(one.shape == (p.height, p.width) and np.array_equal(one, got[5]), f"{path}: eval_dir of one light")
    below = d[:, 2] <= 0
    check(below.sum() >= 3 and np.all(got[below] == 1.0), f"{path}: lights at or below the horizon give K = 1")
    uv = uv_pairs()
    ref = rust_k(path, [f"{float(u)!r},{float(v)!r}" for u, v in uv])
    got = p.eval_xy(uv[:, 0], uv[:, 1])
    err = max(err, float(np.abs(got.astype(np.float64) - ref).max()))
    check(np.array_equal(p.eval_xy(float(uv[3, 0]), float(uv[3, 1])), got[3]), f"{path}: eval_xy of one (lx, ly)")
    check(np.array_equal(p.eval_xy(uv[:, 0], float(uv[3, 1]))[3], got[3]), f"{path}: eval_xy with ly a number")
    check(np.array_equal(p.eval_xy(lx=uv[:5, 0].tolist(), ly=uv[:5, 1].tolist()), got[:5]),
          f"{path}: eval_xy of lists, by keyword")
    # eval_xy takes the projected direction: on every map, K of l is eval_xy(l·T, l·B).
    d = directions()
    d = d[d[:, 2] > 0.1]
    dk = np.abs(p.eval_xy(d[:, 0], d[:, 1]).astype(np.float64) - p.eval_dir(d)).max()
    check(dk <= 1e-4, f"{path}: eval_xy(l·T, l·B) = eval_dir(l) (|ΔK| {dk:.1e}, f32 against f64 directions)")
    check(got.min() >= 0 and got.max() <= 1, f"{path}: K clamped to [0, 1]")
    check(err <= TOL, f"{path}: Python eval = Rust eval (worst |ΔK| {err:.1e})")
    return err


def same_file(a, b, what, storage=None):
    """a and b hold the same PTM: attributes, coefficients, coverage, MIP levels, metadata
    (but `ptm:storage`, which says `storage` in b when given)."""
    ok = (a.basis, a.link, a.uv, a.width, a.height, a.tile, a.monomials) == \
        (b.basis, b.link, b.uv, b.width, b.height, b.tile, b.monomials)
    check(ok, f"{what}: basis, link, uv, size, tile, monomials")
    ca = a.coefficients
    if storage == "half":
        ca = ca.astype(np.float16).astype(np.float32)
    check(np.array_equal(ca, b.coefficients), f"{what}: coefficients")
    check((a.coverage is None) == (b.coverage is None)
          and (a.coverage is None or np.array_equal(a.coverage if storage != "half" else
                                                    a.coverage.astype(np.float16).astype(np.float32),
                                                    b.coverage)), f"{what}: coverage")
    ma, mb = a.mips, b.mips
    check(len(ma) == len(mb) and all(np.array_equal(x if storage != "half" else x.astype(np.float16).astype(np.float32), y)
                                     for x, y in zip(ma, mb)), f"{what}: {len(ma)} MIP levels")
    da, db = a.metadata, b.metadata
    if storage is not None:
        check(db.get("ptm:storage") == storage, f"{what}: ptm:storage = {storage}")
        da, db = dict(da), dict(db)
        da.pop("ptm:storage", None)
        db.pop("ptm:storage", None)
    check(da == db, f"{what}: metadata ({sorted(set(da.items()) ^ set(db.items()))[:4]})")


def expect_error(kind, needle, fn, what):
    try:
        fn()
    except kind as e:
        check(needle in str(e), f"{what}: {kind.__name__} names {needle!r} ({e})")
        return e
    except Exception as e:  # noqa: BLE001 — the wrong exception is the failure reported
        check(False, f"{what}: raises {kind.__name__}, not {type(e).__name__}: {e}")
        return None
    check(False, f"{what}: raises {kind.__name__}")
    return None


# Bakes: a plain weave, and a half-covered tile (holes: coverage 0) made from an OBJ.
run("bake", "--res", "24", "--spp", "2", "--dirs", "48", "-o", "s.exr")
with open(w("half.obj"), "w") as f:
    f.write("v 0 0 0\nv 0.6 0 0\nv 0.6 1 0\nv 0 1 0\n"
            "v 0.2 0.2 0.1\nv 0.4 0.2 0.1\nv 0.4 0.8 0.1\nv 0.2 0.8 0.1\n"
            "f 1 2 3\nf 1 3 4\nf 5 6 7\nf 5 7 8\n")
run("bake", "--swatch", "half.obj", "--tile", "1,1", "--res", "16", "--spp", "2", "--dirs", "48", "-o", "holes.exr")

kinds = []
for basis in ["ptm6", "ptm11"]:
    for link in ["identity", "logistic"]:
        for uv in ["projected", "hemispherical"]:
            name = f"{basis}-{link}-{uv}.ptm.exr"
            extra = {("ptm6", "identity"): ["--no-mips"], ("ptm11", "identity"): ["--half", "--error-map"],
                     ("ptm6", "logistic"): ["--layout", "rgba"], ("ptm11", "logistic"): []}[(basis, link)]
            run("fit", "s.exr", "--basis", basis, "--link", link, "--uv", uv, *extra, "-o", name)
            kinds.append((name, basis, link, uv, extra))
run("fit", "holes.exr", "--basis", "ptm6", "--link", "identity", "--uv", "projected", "-o", "holes.ptm.exr")
kinds.append(("holes.ptm.exr", "ptm6", "identity", "projected", []))

worst = 0.0
t_load = 0.0
for name, basis, link, uv, extra in kinds:
    path = w(name)
    t0 = time.perf_counter()
    p = ptm.load(path)
    t_load += time.perf_counter() - t0
    rgba = "rgba" in extra
    check((p.basis, p.link, p.uv) == (basis, link, uv), f"{name}: basis, link, uv = {(p.basis, p.link, p.uv)}")
    check(p.layout == ("rgba" if rgba else "channels"), f"{name}: loaded from layout {p.layout}")
    check(p.coefficients.shape == (len(p.monomials), p.height, p.width) and p.coefficients.dtype == np.float32,
          f"{name}: coefficients (terms, height, width) float32")
    md = p.metadata
    check(md.get("ptm:basis") == basis and md.get("ptm:nLights") == 48 and isinstance(md.get("ptm:rmsMean"), float)
          and md.get("ptm:monomials") == tuple(p.monomials), f"{name}: metadata has the fit's header ({sorted(md)[:3]}…)")
    check(md.get("ptm:storage") == ("half" if "--half" in extra else "float32"), f"{name}: ptm:storage")
    check((len(p.mips) > 0) == ("--no-mips" not in extra), f"{name}: {len(p.mips)} MIP levels")
    if name.startswith("holes"):
        check(p.coverage is not None and p.coverage.min() == 0 and p.coverage.max() == 1,
              f"{name}: coverage with holes")
    worst = max(worst, compare_eval(path if not rgba else path.replace(".exr", ".c0.exr"), p))
    if rgba:
        # The stem names the renderer layout too.
        check(ptm.load(path).layout == "rgba", f"{name}: the stem loads the rgba parts")
    # Round trips: both layouts, float and half; Rust reads what Python wrote.
    for layout in ["channels", "rgba"]:
        for half in [False, True]:
            out = w(f"rt-{layout}-{int(half)}-{name}")
            written = p.save(out, half=half, layout=layout)
            want = [out] if layout == "channels" else [out.replace(".exr", f".c{i}.exr") for i in range(2 if basis == "ptm6" else 3)]
            if "--error-map" in extra and layout == "rgba":
                want.append(out.replace(".exr", ".err.exr"))
            check(sorted(written) == sorted(want), f"{name} → {layout} half={half}: files {written}")
            q = ptm.load(out)
            same_file(p, q, f"{name} → {layout} half={half}", storage="half" if half else "float32")
            if layout == "rgba" and not half:
                worst = max(worst, compare_eval(out, q))
    if name == "ptm11-identity-hemispherical.ptm.exr":
        # A half file saved as float32 is exact; error maps survive (both layouts).
        back = ptm.load(w(f"rt-channels-0-{name}"))
        check(np.array_equal(back.coefficients, p.coefficients), f"{name}: half → float32 exact")
        same_file(p, ptm.load(w(f"rt-rgba-1-{name}")), f"{name}: half → rgba half", storage="half")

# A PTM built from arrays: coverage, MIP levels, written in both layouts, read back by Rust.
rng = np.random.default_rng(7)
for basis, n in [("ptm6", 6), ("ptm11", 11)]:
    for link in ["identity", "logistic"]:
        for uv in ["projected", "hemispherical"]:
            h, wd = 10, 13
            coeffs = rng.normal(0, 2, (n, h, wd)).astype(np.float32)
            cov = np.ones((h, wd), np.float32)
            cov[2:5, 3:9] = 0
            sizes, (x, y) = [], (wd, h)
            while x > 1 or y > 1:
                x, y = max(x // 2, 1), max(y // 2, 1)
                sizes.append((y, x))
            mips = [rng.normal(0, 1, (n, a, b)) for a, b in sizes]  # float64: cast to float32
            b = ptm.Ptm(basis, coeffs, tile=(2.0, 1.5), link=link, uv=uv, coverage=cov, mips=mips)
            check(b.layout is None and b.metadata.get("ptm:basis") == basis and b.metadata.get("ptm:link") == link,
                  f"built {basis} {link} {uv}: metadata of the file it would write")
            for layout in ["channels", "rgba"]:
                out = w(f"built-{basis}-{link}-{uv}-{layout}.ptm.exr")
                b.save(out, layout=layout)
                q = ptm.load(out)
                check(q.tile == (2.0, 1.5) and np.array_equal(q.coefficients, coeffs)
                      and np.array_equal(q.coverage, cov) and len(q.mips) == len(sizes)
                      and all(np.array_equal(m.astype(np.float32), qm) for m, qm in zip(mips, q.mips)),
                      f"built {basis} {link} {uv} → {layout}: coefficients, coverage, MIP levels")
                same_file(b, q, f"built {basis} {link} {uv} → {layout}")
                worst = max(worst, compare_eval(out if layout == "channels" else out.replace(".exr", ".c0.exr"), q))
            hb = w(f"built-{basis}-{link}-{uv}-half.ptm.exr")
            b.save(hb, half=True)
            same_file(b, ptm.load(hb), f"built {basis} {link} {uv} → half", storage="half")

# Errors: they name the file.
missing = w("no-such.ptm.exr")
e = expect_error(FileNotFoundError, "no-such.ptm.exr", lambda: ptm.load(missing), "a missing file")
check(e is not None and isinstance(e, OSError) and e.filename == missing, "a missing file: OSError with filename")
expect_error(ValueError, "s.exr: not an occlusion PTM", lambda: ptm.load(w("s.exr")), "a non-PTM EXR (the sample stack)")
with open(w("text.exr"), "w") as f:
    f.write("not an EXR\n")
expect_error(ValueError, "text.exr: not a readable OpenEXR file", lambda: ptm.load(w("text.exr")), "a file that is no EXR")
# A file cut short, in its header or its pixels: named once, and called possibly truncated.
with open(w("ptm6-identity-projected.ptm.exr"), "rb") as f:
    whole = f.read()
for keep in (40, len(whole) // 2):
    with open(w("cut.ptm.exr"), "wb") as f:
        f.write(whole[:keep])
    e = expect_error(ValueError, "(truncated or foreign?)", lambda: ptm.load(w("cut.ptm.exr")),
                     f"a PTM cut at {keep} bytes")
    check(e is not None and str(e).count("cut.ptm.exr") == 1, f"a PTM cut at {keep} bytes: named once ({e})")
# A header that Ptm::load refuses is refused here too (written by Python OpenEXR).
src = OpenEXR.File(w("ptm6-identity-projected.ptm.exr"))
for key, value, needle in [("ptm:version", "occlusion-ptm/9", "occlusion-ptm/9"),
                           ("ptm:monomials", ["u", "v"], "`ptm:monomials` does not match basis ptm6")]:
    h = src.header()
    kept = h[key]
    h[key] = value
    src.write(w("odd.ptm.exr"))
    h[key] = kept
    expect_error(ValueError, "odd.ptm.exr: ", lambda: ptm.load(w("odd.ptm.exr")), f"an unknown {key}")
    expect_error(ValueError, needle, lambda: ptm.load(w("odd.ptm.exr")), f"an unknown {key}")
p = ptm.load(w("ptm11-logistic-projected.ptm.exr"))
p.save(w("gap.ptm.exr"), layout="rgba")
os.remove(w("gap.ptm.c1.exr"))
expect_error(ValueError, "gap.ptm.c1.exr: missing part c1", lambda: ptm.load(w("gap.ptm.c0.exr")),
             "an rgba layout with a part missing")
expect_error(ValueError, "unknown layout", lambda: p.save(w("x.exr"), layout="planar"), "save(layout=…) unknown")
# The CLI's names only: the old "single" says what it is called now, and writes nothing.
expect_error(ValueError, 'now called "channels"', lambda: p.save(w("old.ptm.exr"), layout="single"),
             'save(layout="single")')
check(not os.path.exists(w("old.ptm.exr")), 'save(layout="single") writes nothing')
check(p.save(w("default.ptm.exr")) == [w("default.ptm.exr")] and ptm.load(w("default.ptm.exr")).layout == "channels",
      "save() writes the channels layout by default")
# eval(u, v), the old name of eval_xy, warns loudly (a FutureWarning, shown by default) and still
# evaluates as eval_xy.
import warnings  # noqa: E402
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("default")
    old = p.eval(0.3, 0.2)
check(any(issubclass(c.category, FutureWarning) and "eval_xy(lx, ly)" in str(c.message) for c in caught),
      f"eval(u, v) warns, naming eval_xy ({[str(c.message) for c in caught]})")
check(np.array_equal(old, p.eval_xy(0.3, 0.2)), "eval(u, v) = eval_xy(lx, ly)")
expect_error(FileNotFoundError, "no-dir", lambda: p.save(w("no-dir/x.ptm.exr")), "save into a missing folder")
big = ptm.Ptm("ptm6", np.full((6, 2, 2), 1e5, np.float32))
expect_error(ValueError, "big.ptm.exr: a coefficient of magnitude", lambda: big.save(w("big.ptm.exr"), half=True),
             "half overflow")
check(not os.path.exists(w("big.ptm.exr")), "half overflow writes nothing")
expect_error(ValueError, "unknown basis", lambda: ptm.Ptm("ptm7", np.zeros((6, 2, 2))), "Ptm(basis) unknown")
expect_error(ValueError, "ptm11 needs (11, height, width)", lambda: ptm.Ptm("ptm11", np.zeros((6, 2, 2))),
             "Ptm(coefficients) with the wrong number of planes")
expect_error(ValueError, "coverage", lambda: ptm.Ptm("ptm6", np.zeros((6, 2, 2)), coverage=np.full((2, 2), 2.0)),
             "Ptm(coverage) outside [0, 1]")
expect_error(ValueError, "unknown link", lambda: ptm.Ptm("ptm6", np.zeros((6, 2, 2)), link="probit"), "Ptm(link) unknown")
expect_error(ValueError, "MIP levels", lambda: ptm.Ptm("ptm6", np.zeros((6, 4, 4)), mips=[np.zeros((6, 2, 2))]),
             "Ptm(mips) not the whole chain")
expect_error(ValueError, "(N, 3)", lambda: p.eval_dir([0.0, 1.0]), "eval_dir of a 2-vector")
expect_error(ValueError, "lights", lambda: p.eval_xy([0.1, 0.2], [0.1, 0.2, 0.3]), "eval_xy of lx, ly of different lengths")

# The Python example of docs/pipeline.md, run as written on a renderer-layout PTM named w.ptm.
readme = open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "docs", "pipeline.md")).read()
block = readme.split("<!-- readme-python-module -->\n```python\n", 1)[1].split("```", 1)[0]
run("convert", "ptm11-logistic-hemispherical.ptm.exr", "-o", "w.ptm.exr", "--layout", "rgba")
cwd = os.getcwd()
os.chdir(WORK)
scope = {}
try:
    exec(compile(block, "docs/pipeline.md (Python module example)", "exec"), scope)
except Exception as e:  # noqa: BLE001
    check(False, f"README Python module example runs ({type(e).__name__}: {e})")
os.chdir(cwd)
check(scope.get("K") is not None and scope["K"].shape == (64, 24, 24), "README example: K of 64 lights")
check(os.path.exists(w("flat.ptm.c1.exr")), "README example: wrote the rgba layout of a built PTM")

# Speed: 1024 lights × a 256×256 PTM, against numpy doing the same sum as one matrix product.
speed = []
for basis, n in [("ptm6", 6), ("ptm11", 11)]:
    for link in ["identity", "logistic"]:
        coeffs = rng.normal(0, 1, (n, 256, 256)).astype(np.float32)
        b = ptm.Ptm(basis, coeffs, link=link)
        d = directions()
        d = d[d[:, 2] > 0]
        d = np.resize(d, (1024, 3))
        b.eval_dir(d[:8])
        t0 = time.perf_counter()
        k = b.eval_dir(d)
        dt = time.perf_counter() - t0
        # numpy doing the same: each light's terms times the planes as one matrix product (BLAS).
        t0 = time.perf_counter()
        u, v = d[:, 0].astype(np.float32), d[:, 1].astype(np.float32)
        kn = np.stack([u ** POW[t][0] * v ** POW[t][1] for t in b.monomials], axis=1) @ coeffs.reshape(n, -1)
        if link == "logistic":
            kn = 1 / (1 + np.exp(-kn))
        np.clip(kn, 0, 1, out=kn)
        dn = time.perf_counter() - t0
        check(np.abs(kn.reshape(k.shape) - k).max() < 1e-4, f"speed {basis} {link}: numpy's K agrees")
        speed.append(f"{basis} {link} {k.size / dt / 1e6:.0f} (numpy matmul {k.size / dn / 1e6:.0f})")
print(f"python module: {len(kinds)} fitted PTMs + 8 built from arrays, eval/eval_dir vs Rust Ptm::eval worst "
      f"|ΔK| {worst:.1e} (tolerance {TOL:.0e}); round trips channels/rgba × float/half; "
      f"loads {t_load * 1e3 / len(kinds):.1f} ms each; eval_dir 1024 lights × 256² texels, Mtexel-evals/s: "
      + ", ".join(speed))
if failures:
    print(f"python module: {len(failures)} failed")
    sys.exit(1)
