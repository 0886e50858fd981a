"""OSL from MaterialX's own OSL generator for ND_ptm_occlusion_float, as one self-contained file
a renderer's OSL compiler takes (the client test compiles it with Cycles' and renders K).

The generated shader is for the output of a small nodegraph: a ptm_occlusion node whose inputs
are the shader's parameters (`part0..2`, `basis`, `link`, `uvmap`, `filtertype`, the light
direction `light`, the texture coordinates `uv` (a vector, its x and y; Cycles' `u, v` globals
are the triangle's, not the UV map's) and the UV `tangent`); the normal is MaterialX's Nworld
geomprop. MaterialX's `#include "mx_funcs.h"` (libraries/stdlib/genosl/include) is inlined,
`#pragma once` files once.

fileTextureVerticalFlip: MaterialX's image uv has (0, 0) at the image's bottom-left; OSL's
texture() t = 0 is the file's first row (its top). The OSL generator flips v only when the
GenOptions say so (default: not), so a renderer must set it (as `generate(flip=True)` does).

    python mtlx_osl.py OUT.osl [--no-flip] [--learned]   # --learned: ND_ptm_occlusion_learned_float
"""
import os
import re
import sys

import MaterialX as mx
import MaterialX.PyMaterialXGenOsl as mx_osl
import MaterialX.PyMaterialXGenShader as mx_gen

HERE = os.path.dirname(os.path.abspath(__file__))
COMMON = [("uv", "vector3", "0, 0, 0"), ("light", "vector3", "0, 0, 1"),
          ("tangent", "vector3", "1, 0, 0")]
PARAMS = COMMON + [("part0", "filename", ""), ("part1", "filename", ""),
                   ("part2", "filename", ""), ("basis", "integer", "6"), ("link", "integer", "0"),
                   ("uvmap", "integer", "0"), ("filtertype", "string", "linear")]
# ND_ptm_occlusion_learned_float (`--learned`): parts, basis parts, the grid side.
PARAMS_LEARNED = COMMON + [(f"part{i}", "filename", "") for i in range(4)] + \
    [(f"basis{i}", "filename", "") for i in range(4)] + \
    [("grid", "integer", "17"), ("filtertype", "string", "linear")]


def graph_doc(learned=False):
    """ptm_occlusion.mtlx plus NG_ptm_k: the K of its node (ptm_occlusion, or
    ptm_occlusion_learned) with every input a nodegraph input."""
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, os.path.join(HERE, "ptm_occlusion.mtlx"))
    ng = doc.addNodeGraph("NG_ptm_k")
    params = PARAMS_LEARNED if learned else PARAMS
    for name, typ, val in params:
        ng.addInput(name, typ).setValueString(val)
    uv2 = ng.addNode("convert", "uv2", "vector2")
    uv2.addInput("in", "vector3").setInterfaceName("uv")
    k = ng.addNode("ptm_occlusion_learned" if learned else "ptm_occlusion", "K", "float")
    k.addInput("texcoord", "vector2").setConnectedNode(uv2)
    for name, typ, _ in params:
        if name != "uv":
            k.addInput("light_dir" if name == "light" else name, typ).setInterfaceName(name)
    ng.addOutput("out", "float").setConnectedNode(k)
    return doc


def flatten(src, dirs, seen=None):
    """`src` with every `#include "f"` replaced by f (searched in dirs), `#pragma once` honoured."""
    seen = set() if seen is None else seen
    out = []
    for line in src.splitlines():
        m = re.match(r'\s*#include\s+"([^"]+)"', line)
        if not m:
            out.append("" if line.strip() == "#pragma once" else line)
            continue
        path = next((os.path.join(d, m.group(1)) for d in dirs if os.path.isfile(os.path.join(d, m.group(1)))), None)
        if path is None:
            raise FileNotFoundError(f"#include \"{m.group(1)}\" not found in {dirs}")
        path = os.path.realpath(path)
        if path in seen:
            continue
        seen.add(path)
        text = open(path).read()
        out.append(f"// ---- {m.group(1)} (MaterialX libraries, inlined)")
        out.append(flatten(text, [os.path.dirname(path)] + dirs, seen))
    return "\n".join(out) + "\n"


def generate(flip=True, learned=False):
    """(self-contained OSL source, shader name) for NG_ptm_k's output."""
    doc = graph_doc(learned)
    lib = mx.createDocument()
    search = mx.getDefaultDataSearchPath()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), search, lib)
    doc.importLibrary(lib)
    ok, msg = doc.validate()
    assert ok, msg
    gen = mx_osl.OslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(search)
    ctx.getOptions().fileTextureVerticalFlip = flip
    name = ("ptm_k_learned" if learned else "ptm_k") + ("" if flip else "_noflip")
    shader = gen.generate(name, doc.getNodeGraph("NG_ptm_k").getOutput("out"), ctx)
    src = shader.getSourceCode(mx_gen.PIXEL_STAGE)
    inc = [os.path.join(d, "libraries", "stdlib", "genosl", "include")
           for d in search.asString().split(mx.PATH_LIST_SEPARATOR)]
    return flatten(src, inc), name


if __name__ == "__main__":
    src, _ = generate(flip="--no-flip" not in sys.argv[2:], learned="--learned" in sys.argv[2:])
    open(sys.argv[1], "w").write(src)
    print(f"wrote {sys.argv[1]} ({src.count(chr(10))} lines)")
