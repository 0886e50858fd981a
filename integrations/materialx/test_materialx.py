"""MaterialX check (default test suite): ptm_occlusion.mtlx is what make_mtlx.py writes, it and
the example material validate against the standard libraries, MaterialX's own generators
produce OSL and GLSL from them, and glslangValidator compiles the GLSL. Then the numbers:
ND_ptm_occlusion_float's nodegraph, evaluated node by node in numpy (mx_numpy.py), gives the K
of Rust `Ptm::eval_dir` (fit/examples/ptm_eval.rs) at every texel centre of renderer-layout PTMs
fitted by the `ptm` binary (ptm6 and ptm11, both links, both (u, v) maps), for lights from the
zenith down to grazing and below the horizon, in the swatch frame and in a rotated world frame;
and between texel centres with linear filtering (across the periodic seams), the K of the
bilinearly filtered coefficients (the `ptm` Python module reads and evaluates them).

    python test_materialx.py PTM_BIN PTM_EVAL WORKDIR
"""
import json
import os
import subprocess
import sys
import time

import MaterialX as mx
import MaterialX.PyMaterialXGenGlsl as mx_glsl
import MaterialX.PyMaterialXGenOsl as mx_osl
import MaterialX.PyMaterialXGenShader as mx_gen

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import make_mtlx  # noqa: E402
import mx_numpy  # noqa: E402
import numpy as np  # noqa: E402
import ptm as ptm_module  # noqa: E402  the Python module (scripts/test.sh builds it first)

PTM, EVAL, WORK = sys.argv[1:4]
os.makedirs(WORK, exist_ok=True)

fresh = os.path.join(WORK, "fresh.mtlx")
mx.writeToXmlFile(make_mtlx.build(), fresh)
committed = os.path.join(HERE, "ptm_occlusion.mtlx")
assert open(fresh).read() == open(committed).read(), "ptm_occlusion.mtlx is stale: run make_mtlx.py"

# MaterialX's OSL and GLSL generators write float constants with 6 decimals, whatever the
# document holds: a constant that does not survive that is another constant in the shader
# (1e-20 was 0.000000, so 0 / 0 at the zenith; π/2 was 1.570800).
own = mx.createDocument()
mx.readFromXmlFile(own, committed)
for elem in [own.getNodeDef("ND_ptm_occlusion_float"), own.getNodeDef("ND_ptm_occlusion_learned_float")] + \
        list(own.getNodeGraph("NG_ptm_occlusion_float").getNodes()) + \
        list(own.getNodeGraph("NG_ptm_occlusion_learned_float").getNodes()):
    for inp in elem.getInputs():
        if inp.getType() in ("float", "vector2", "vector3", "vector4", "color3", "color4") and inp.hasValueString():
            for x in inp.getValueString().split(","):
                assert float(f"{float(x):.6f}") == float(x), f"{inp.getNamePath()} = {x}: not kept by 6-decimal code"
lib = mx.createDocument()
search = mx.getDefaultDataSearchPath()
mx.loadLibraries(mx.getDefaultDataLibraryFolders(), search, lib)
counts = {}
EXAMPLES = {"example.mtlx": ("ND_ptm_occlusion_float", "NG_ptm_occlusion_float", "M_cloth"),
            "example_learned.mtlx": ("ND_ptm_occlusion_learned_float", "NG_ptm_occlusion_learned_float",
                                     "M_cloth_learned")}
for name in ("ptm_occlusion.mtlx", "example.mtlx", "example_learned.mtlx"):
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, os.path.join(HERE, name), mx.FileSearchPath(HERE))
    doc.importLibrary(lib)
    ok, msg = doc.validate()
    assert ok, f"{name}: {msg}"
    if name in EXAMPLES:
        nd_name, ng_name, material = EXAMPLES[name]
        tag = name[:-5]
        nd = doc.getNodeDef(nd_name)
        impl = nd.getImplementation()
        assert impl is not None and impl.getName() == ng_name
        assert all(n.getNodeDef() is not None for n in impl.getNodes()), "non-standard node in the graph"
        counts[f"{tag}: graph nodes"] = len(impl.getNodes())
        target = doc.getChild(material)
        for gen, ext in ((mx_osl.OslShaderGenerator.create(), "osl"),
                         (mx_glsl.GlslShaderGenerator.create(), "glsl")):
            ctx = mx_gen.GenContext(gen)
            ctx.registerSourceCodeSearchPath(search)
            shader = gen.generate("ptm_cloth", target, ctx)
            if ext == "osl":
                src = shader.getSourceCode(mx_gen.PIXEL_STAGE)
                assert "ptm" in src and "texture(" in src, "generated OSL does not sample the parts"
                open(os.path.join(WORK, f"{tag}.osl"), "w").write(src)
                counts[f"{tag}: osl lines"] = src.count("\n")
            else:
                for stage, flag in ((mx_gen.VERTEX_STAGE, "vert"), (mx_gen.PIXEL_STAGE, "frag")):
                    path = os.path.join(WORK, f"{tag}.{flag}")
                    open(path, "w").write(shader.getSourceCode(stage))
                    r = subprocess.run(["glslangValidator", path], capture_output=True, text=True)
                    assert r.returncode == 0, f"glslangValidator {path}:\n{r.stdout}{r.stderr}"
                counts[f"{tag}: glsl compiled"] = 2
# docs/pipeline.md's MaterialX examples are the nodes of example.mtlx and example_learned.mtlx.
doc = open(os.path.join(HERE, "..", "..", "docs", "pipeline.md")).read()
blocks = [b.split("```", 1)[0] for b in doc.split("```xml\n")[1:]]
assert len(blocks) == 2, f"docs/pipeline.md has {len(blocks)} MaterialX examples, not 2"
for block, name in zip(blocks, ("example.mtlx", "example_learned.mtlx")):
    example = open(os.path.join(HERE, name)).read()
    assert all(line.strip() in example for line in block.splitlines()), f"docs/pipeline.md's MaterialX example differs from {name}"
print(f"materialx: ND_ptm_occlusion_float and ND_ptm_occlusion_learned_float validate; OSL and GLSL generated, "
      f"GLSL compiled by glslangValidator ({counts})")

# --- K of the nodegraph, evaluated in numpy, against Ptm::eval ---------------------------------
TOL = 1e-5
RES = 16
t0 = time.time()


def ptm(*args):
    subprocess.run([PTM, *args], check=True, capture_output=True, cwd=WORK)


def toward(elev_deg, azim_deg):
    e, a = np.radians(elev_deg), np.radians(azim_deg)
    return (float(np.cos(e) * np.cos(a)), float(np.cos(e) * np.sin(a)), float(np.sin(e)))


# Towards the light, swatch frame: zenith (and just off it, where the hemispherical map's
# r → 0), mid elevations, grazing down to 0.05°, the horizon and below it (K = 1).
DIRS = [(0.0, 0.0, 1.0), (1e-4, -2e-4, 1.0), (0.6, 0.2, 0.5), (-0.5, 0.7, 0.4), (0.3, -0.8, 0.35),
        (-0.9, -0.3, 0.25), toward(10, 200), toward(3, 35), toward(1, 120), toward(0.3, 250),
        toward(0.05, 300), (1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.3, 0.2, -0.1), (0.0, 0.0, -1.0)]
ptm("bake", "--res", str(RES), "--spp", "4", "--dirs", "64", "-o", "s.exr")
lib_doc = mx.createDocument()
mx.readFromXmlFile(lib_doc, committed)

# A world frame for the second pass: rotation R, a tangent that is neither unit nor orthogonal
# to N (the graph orthonormalises it), a light vector that is not unit (the graph normalises).
ax = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
ang = 0.9
K_ = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
R = np.eye(3) + np.sin(ang) * K_ + (1 - np.cos(ang)) * K_ @ K_
jj, ii = np.meshgrid(np.arange(RES), np.arange(RES), indexing="ij")  # row j, column i
uv_tex = np.stack([(ii + 0.5) / RES, 1 - (jj + 0.5) / RES], axis=-1).reshape(-1, 2)
npts = uv_tex.shape[0]
FRAMES = {
    "swatch frame": (uv_tex, np.tile([0.0, 0.0, 1.0], (npts, 1)), np.tile([1.0, 0.0, 0.0], (npts, 1)),
                     np.eye(3), 1.0),
    # UVs one tile over (periodic addressing), the frame rotated by R.
    "rotated frame": (uv_tex + [1.0, -2.0], np.tile(R[:, 2], (npts, 1)),
                      np.tile(2.0 * R[:, 0] + 0.3 * R[:, 2], (npts, 1)), R, 3.0),
}
# Points between texel centres, some within a hair of the periodic seams, and the lights there.
rng = np.random.default_rng(11)
uv_mid = np.concatenate([rng.random((400, 2)), [[1e-4, 0.5], [1 - 1e-4, 0.3], [0.5, 1e-4], [0.2, 1 - 1e-4],
                                                [0.0, 0.0], [1.0, 1.0]]])
MID_DIRS = [np.array(d) / np.linalg.norm(d) for d in DIRS[:6] + [toward(3, 35)]]
worst_all = {}
used = set()
for basis in ("ptm6", "ptm11"):
    for link in ("identity", "logistic"):
        for uvmap in ("projected", "hemispherical"):
            stem = f"{basis}-{link}-{uvmap}.ptm"
            ptm("fit", "s.exr", "--basis", basis, "--link", link, "--uv", uvmap, "--layout", "rgba",
                "-o", stem + ".exr")
            ref = np.array(json.loads(subprocess.run(
                [EVAL, os.path.join(WORK, stem + ".c0.exr")] + [",".join(map(repr, d)) for d in DIRS],
                check=True, capture_output=True, text=True).stdout)).reshape(len(DIRS), -1)
            assert ref[2].max() - ref[2].min() > 0.05, f"{stem}: K is flat; the check would prove nothing"
            assert ((ref > 1e-3) & (ref < 1 - 1e-3)).any(), f"{stem}: K is all clamped"
            worst = 0.0
            doc = mx.createDocument()
            doc.importLibrary(lib_doc)
            doc.importLibrary(lib)
            node = doc.addNode("ptm_occlusion", "K", "float")
            for k in range(3 if basis == "ptm11" else 2):
                node.setInputValue(f"part{k}", f"{stem}.c{k}.exr", "filename")
            node.setInputValue("basis", 11 if basis == "ptm11" else 6, "integer")
            node.setInputValue("link", 1 if link == "logistic" else 0, "integer")
            node.setInputValue("uvmap", 1 if uvmap == "hemispherical" else 0, "integer")
            light = node.addInput("light_dir", "vector3")
            light.setValueString("0, 0, 1")
            filt = node.addInput("filtertype", "string")
            filt.setValueString("linear")
            ok, msg = doc.validate()
            assert ok, msg
            for fname, (uv, nrm, tan, rot, scale) in FRAMES.items():
                ev = mx_numpy.Evaluator({"UV0": uv, "Nworld": nrm, "Tworld": tan}, root=WORK)
                for ft in ("linear", "closest"):
                    filt.setValueString(ft)
                    for di, d in enumerate(DIRS):
                        if fname != "swatch frame" and d[2] == 0.0:
                            continue  # exactly on the horizon: rounding in R decides the side
                        # As a string: MaterialX's own formatting (setInputValue) keeps 6 digits.
                        light.setValueString(", ".join(repr(float(x)) for x in scale * rot @ np.array(d)))
                        k = ev.node(node)
                        assert k.shape == (npts,) and np.isfinite(k).all(), f"{stem}: K not finite for {d}"
                        err = float(np.abs(k - ref[di]).max())
                        assert err <= TOL, (f"{stem} {fname} {ft} light {d}: nodegraph K differs from "
                                            f"Ptm::eval by {err:.2e} (tolerance {TOL})")
                        worst = max(worst, err)
                used |= ev.used
            # Between texel centres (linear filtering, across the periodic seams): the file's
            # meaning is "filter the coefficients, then evaluate the polynomial and the link".
            # Reference: the coefficients (read by the ptm module) interpolated bilinearly at
            # MaterialX's image uv, then Rust's eval of them (the module's eval_dir is Ptm's).
            src = ptm_module.load(os.path.join(WORK, stem + ".c0.exr"))
            coef = src.coefficients.astype(np.float64)
            _, hh, ww = coef.shape
            x, y = uv_mid[:, 0] * ww - 0.5, (1.0 - uv_mid[:, 1]) * hh - 0.5
            x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
            fx, fy = x - x0, y - y0
            at = lambda r, c: coef[:, np.mod(r, hh), np.mod(c, ww)]  # noqa: E731
            mid = ((1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1))
                   + fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1)))
            ref_mid = ptm_module.Ptm(basis, mid[:, None, :].astype(np.float32), tile=src.tile, link=link,
                                     uv=uvmap).eval_dir(np.array(MID_DIRS))[:, 0, :]
            ev = mx_numpy.Evaluator({"UV0": uv_mid, "Nworld": np.tile([0.0, 0.0, 1.0], (len(uv_mid), 1)),
                                     "Tworld": np.tile([1.0, 0.0, 0.0], (len(uv_mid), 1))}, root=WORK)
            filt.setValueString("linear")
            for di, d in enumerate(MID_DIRS):
                light.setValueString(", ".join(repr(float(x)) for x in d))
                err = float(np.abs(ev.node(node) - ref_mid[di]).max())
                assert err <= TOL, (f"{stem} between texels, light {d}: nodegraph K differs from the "
                                    f"bilinearly filtered coefficients' K by {err:.2e} (tolerance {TOL})")
                worst = max(worst, err)
            worst_all[f"{basis} {link} {uvmap}"] = worst
            print(f"materialx: {basis} {link} {uvmap}: max |K(nodegraph, numpy) - Ptm::eval| = {worst:.1e} "
                  f"over {len(DIRS)} lights x 2 frames x 2 filters x {npts} texel centres, and "
                  f"{len(MID_DIRS)} lights x {len(uv_mid)} points between them", flush=True)

# --- The learned basis: ND_ptm_occlusion_learned_float on files `ptm fit --basis learnedN` wrote --
sys.path.insert(0, os.path.join(HERE, "..", "osl"))
import ptm_params  # noqa: E402  the OSL / MaterialX / Blender side's reader of the parts


def table_read(table, grid, u, v):
    """B_k(u, v) of every term, the docs/FORMAT.md bilinear read of the header's table (rows of
    (points,)): an independent numpy reading of the formula, not of the basis parts."""
    x = (np.clip(u, -1, 1) + 1) / 2 * (grid - 1)
    y = (np.clip(v, -1, 1) + 1) / 2 * (grid - 1)
    i0 = np.minimum(np.floor(x), grid - 2).astype(int)
    j0 = np.minimum(np.floor(y), grid - 2).astype(int)
    fx, fy = x - i0, y - j0
    t = np.asarray(table).reshape(len(table), grid, grid)  # [k][row j][column i]
    return ((1 - fx) * (1 - fy) * t[:, j0, i0] + fx * (1 - fy) * t[:, j0, i0 + 1]
            + (1 - fx) * fy * t[:, j0 + 1, i0] + fx * fy * t[:, j0 + 1, i0 + 1])


def hemispherical(d):
    d = np.asarray(d, dtype=np.float64)
    d = d / np.linalg.norm(d)
    r = np.hypot(d[0], d[1])
    s = np.arctan2(r, d[2]) / (np.pi / 2) / r if r > 0 else 0.0
    return d[0] * s, d[1] * s


def sigma(p):
    e = np.exp(-np.abs(p))
    return np.where(p >= 0, 1 / (1 + e), e / (1 + e))


for terms in (11, 6):  # the terms `ptm fit` learns; format/tests/learned.rs writes 1 … 16
    basis = f"learned{terms}"
    stem = f"{basis}.ptm"
    ptm("fit", "s.exr", "--basis", basis, "--layout", "rgba", "-o", stem + ".exr")
    params = ptm_params.learned_params(os.path.join(WORK, stem + ".c0.exr"))
    assert (params["terms"], len(params["basis_parts"]), len(params["parts"])) == \
        (terms, -(-terms // 4), -(-(terms + 1) // 4)), params
    ref = np.array(json.loads(subprocess.run(
        [EVAL, os.path.join(WORK, stem + ".c0.exr")] + [",".join(map(repr, d)) for d in DIRS],
        check=True, capture_output=True, text=True).stdout)).reshape(len(DIRS), -1)
    assert ref[2].max() - ref[2].min() > 0.05, f"{stem}: K is flat; the check would prove nothing"
    assert ((ref > 1e-3) & (ref < 1 - 1e-3)).any(), f"{stem}: K is all clamped"
    doc = mx.createDocument()
    doc.importLibrary(lib_doc)
    doc.importLibrary(lib)
    node = doc.addNode("ptm_occlusion_learned", "K", "float")
    for i, (part, table) in enumerate(zip(params["parts"], params["basis_parts"])):
        node.setInputValue(f"part{i}", os.path.basename(part), "filename")
        node.setInputValue(f"basis{i}", os.path.basename(table), "filename")
    node.setInputValue("grid", params["grid"], "integer")
    light = node.addInput("light_dir", "vector3")
    light.setValueString("0, 0, 1")
    filt = node.addInput("filtertype", "string")
    filt.setValueString("linear")
    ok, msg = doc.validate()
    assert ok, msg
    worst = 0.0
    for fname, (uv, nrm, tan, rot, scale) in FRAMES.items():
        ev = mx_numpy.Evaluator({"UV0": uv, "Nworld": nrm, "Tworld": tan}, root=WORK)
        for ft in ("linear", "closest"):
            filt.setValueString(ft)
            for di, d in enumerate(DIRS):
                if fname != "swatch frame" and d[2] == 0.0:
                    continue
                light.setValueString(", ".join(repr(float(x)) for x in scale * rot @ np.array(d)))
                k = ev.node(node)
                assert k.shape == (npts,) and np.isfinite(k).all(), f"{stem}: K not finite for {d}"
                err = float(np.abs(k - ref[di]).max())
                assert err <= TOL, (f"{stem} {fname} {ft} light {d}: learned nodegraph K differs from "
                                    f"Ptm::eval by {err:.2e} (tolerance {TOL})")
                worst = max(worst, err)
        used |= ev.used
    # Between texel centres: the coefficients filtered bilinearly (periodic), B_k from the
    # header's table by the FORMAT.md formula (not from the basis parts the graph reads).
    src = ptm_module.load(os.path.join(WORK, stem + ".c0.exr"))
    assert src.basis == basis
    coef = src.coefficients.astype(np.float64)
    _, hh, ww = coef.shape
    x, y = uv_mid[:, 0] * ww - 0.5, (1.0 - uv_mid[:, 1]) * hh - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    at = lambda r, c: coef[:, np.mod(r, hh), np.mod(c, ww)]  # noqa: E731
    mid = ((1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1))
           + fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1)))
    table = [[float(w) for w in t.split(" ")] for t in src.metadata["ptm:learnedTable"]]
    ev = mx_numpy.Evaluator({"UV0": uv_mid, "Nworld": np.tile([0.0, 0.0, 1.0], (len(uv_mid), 1)),
                             "Tworld": np.tile([1.0, 0.0, 0.0], (len(uv_mid), 1))}, root=WORK)
    filt.setValueString("linear")
    for d in MID_DIRS:
        light.setValueString(", ".join(repr(float(x)) for x in d))
        u, v = hemispherical(d)
        b = table_read(table, params["grid"], np.array([u]), np.array([v]))[:, 0]
        want = sigma(b @ mid)
        err = float(np.abs(ev.node(node) - want).max())
        assert err <= TOL, (f"{stem} between texels, light {d}: learned nodegraph K differs from the "
                            f"bilinearly filtered coefficients' K by {err:.2e} (tolerance {TOL})")
        worst = max(worst, err)
    worst_all[basis] = worst
    print(f"materialx: {basis}: max |K(learned nodegraph, numpy) - Ptm::eval| = {worst:.1e} over "
          f"{len(DIRS)} lights x 2 frames x 2 filters x {npts} texel centres, and {len(MID_DIRS)} lights x "
          f"{len(uv_mid)} points between them (parts c0..c{len(params['parts']) - 1}, basis parts "
          f"basis0..basis{len(params['basis_parts']) - 1})", flush=True)

# The parts' reader of the texture-system side (ptm_params, the standard library's struct and
# zlib) decodes the basis parts as OpenImageIO does, and refuses bad ones with the file and
# the figures, as the Rust reader (ptm_eval: layout::load) does.
import OpenEXR  # noqa: E402
import OpenImageIO as oiio  # noqa: E402

good = ptm_params.learned_params(os.path.join(WORK, "learned6.ptm.c0.exr"))
for p in good["basis_parts"]:
    w, h, pix = ptm_params.read_pixels(p)
    img = oiio.ImageInput.open(p)
    px = np.asarray(img.read_image(0, 0, 0, 4, "float"))
    names = list(img.spec().channelnames)
    img.close()
    for c, name in enumerate(names):
        assert np.array_equal(np.asarray(pix[name]).reshape(h, w), px[:, :, c]), f"{p} {name}: decoded differently"


def bad_set(tag, edit):
    """A copy of learned6's files as bad-<tag>.ptm.*, basis part 1 rewritten by `edit`
    (channels by name as (rows, columns) float32 arrays → changed in place or replaced)."""
    import shutil
    dst = os.path.join(WORK, f"bad-{tag}.ptm")
    for p in good["parts"] + good["basis_parts"]:
        shutil.copy(p, dst + p[len(good["stem"]):])
    src = OpenEXR.File(good["basis_parts"][1], separate_channels=True)
    chans = {n: np.array(c.pixels, dtype=np.float32) for n, c in src.channels().items()}
    edit(chans)
    header = {k: v for k, v in src.header().items() if k.startswith("ptm:")}
    header["compression"] = OpenEXR.ZIP_COMPRESSION
    OpenEXR.File(header, chans).write(dst + ".basis1.exr")
    return dst


def refused(tag, edit, want):
    stem = bad_set(tag, edit)
    try:
        ptm_params.learned_params(stem + ".c0.exr")
        raise AssertionError(f"ptm_params read the bad set {tag}")
    except ValueError as e:
        msg = str(e)
    r = subprocess.run([EVAL, stem + ".c0.exr", "0,0,1"], capture_output=True, text=True)
    assert r.returncode != 0, f"ptm_eval read the bad set {tag}"
    for w in want:
        assert w in msg, f"ptm_params, {tag}: want {w!r} in {msg!r}"
        assert w in r.stderr, f"Rust reader, {tag}: want {w!r} in {r.stderr!r}"
    assert f"bad-{tag}.ptm.basis1.exr" in msg and f"bad-{tag}.ptm.basis1.exr" in r.stderr, (msg, r.stderr)
    return msg


G = good["grid"]


def smaller(ch):
    for n in ch:
        ch[n] = np.ascontiguousarray(ch[n][:G - 1, :])


def nonfinite(ch):
    ch["G"][3, 2] = np.nan  # B5 of learned6


def seventh_term(ch):
    ch["B"][1, 2] = 0.25  # past learned6's last term


msgs = [refused("size", smaller, [f"basis part basis1 is {G}×{G - 1}", f"is {G}: a basis part is the {G}×{G} table"]),
        refused("nan", nonfinite, ["channel G (B5) is ", "at column 2, row 3: not a number a renderer can use"]),
        refused("terms", seventh_term, ["channel B holds 0.25 at column 2, row 1", "has 6 terms (B0..B5)"])]
print("materialx: bad basis parts refused alike by ptm_params and the Rust reader: " + "; ".join(
    m.split(": ", 1)[1] for m in msgs), flush=True)

gdoc = mx.createDocument()
gdoc.importLibrary(lib_doc)
gdoc.importLibrary(lib)
graph_defs = {n.getNodeDef().getName() for g in ("NG_ptm_occlusion_float", "NG_ptm_occlusion_learned_float")
              for n in gdoc.getNodeGraph(g).getNodes()}
assert graph_defs <= used, f"nodedefs of the graph never evaluated: {graph_defs - used}"
# The evaluator must refuse what it does not know, not skip it: a graph with a node it lacks.
bad = mx.createDocument()
bad.importLibrary(lib_doc)
bad_ng = bad.getNodeGraph("NG_ptm_occlusion_float")
noise = bad_ng.addNode("noise2d", "noise", "float")
next(n for n in bad_ng.getNodes() if n.getCategory() == "clamp").setConnectedNode("in", noise)
bad.importLibrary(lib)
node = bad.addNode("ptm_occlusion", "K", "float")
try:
    mx_numpy.Evaluator({"UV0": uv_tex, "Nworld": FRAMES["swatch frame"][1], "Tworld": FRAMES["swatch frame"][2]},
                       root=WORK).node(node)
    raise AssertionError("mx_numpy evaluated a noise2d node it does not implement")
except mx_numpy.Unsupported as e:
    assert "noise2d" in str(e), e
print(f"materialx: nodegraph K = Ptm::eval to {max(worst_all.values()):.1e} (tolerance {TOL}) for "
      f"{len(worst_all)} PTMs; {len(used)} standard nodedefs evaluated in numpy; an unknown node "
      f"fails; {time.time() - t0:.1f} s")
