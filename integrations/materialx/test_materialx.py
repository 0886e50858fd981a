"""MaterialX check (default test suite): ptm_occlusion.mtlx is what make_mtlx.py writes, it and
the example material validate against the standard libraries, MaterialX's own generators
produce OSL and GLSL from them, and glslangValidator compiles the GLSL.

    python test_materialx.py WORKDIR
"""
import os
import subprocess
import sys

import MaterialX as mx
import MaterialX.PyMaterialXGenGlsl as mx_glsl
import MaterialX.PyMaterialXGenOsl as mx_osl
import MaterialX.PyMaterialXGenShader as mx_gen

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import make_mtlx  # noqa: E402

WORK = sys.argv[1]
os.makedirs(WORK, exist_ok=True)

fresh = os.path.join(WORK, "fresh.mtlx")
mx.writeToXmlFile(make_mtlx.build(), fresh)
committed = os.path.join(HERE, "ptm_occlusion.mtlx")
assert open(fresh).read() == open(committed).read(), "ptm_occlusion.mtlx is stale: run make_mtlx.py"

lib = mx.createDocument()
search = mx.getDefaultDataSearchPath()
mx.loadLibraries(mx.getDefaultDataLibraryFolders(), search, lib)
counts = {}
for name in ("ptm_occlusion.mtlx", "example.mtlx"):
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, os.path.join(HERE, name), mx.FileSearchPath(HERE))
    doc.importLibrary(lib)
    ok, msg = doc.validate()
    assert ok, f"{name}: {msg}"
    if name == "example.mtlx":
        nd = doc.getNodeDef("ND_ptm_occlusion_float")
        impl = nd.getImplementation()
        assert impl is not None and impl.getName() == "NG_ptm_occlusion_float"
        assert all(n.getNodeDef() is not None for n in impl.getNodes()), "non-standard node in the graph"
        counts["graph nodes"] = len(impl.getNodes())
        target = doc.getChild("M_cloth")
        for gen, ext in ((mx_osl.OslShaderGenerator.create(), "osl"),
                         (mx_glsl.GlslShaderGenerator.create(), "glsl")):
            ctx = mx_gen.GenContext(gen)
            ctx.registerSourceCodeSearchPath(search)
            shader = gen.generate("ptm_cloth", target, ctx)
            if ext == "osl":
                src = shader.getSourceCode(mx_gen.PIXEL_STAGE)
                assert "ptm" in src and "texture(" in src, "generated OSL does not sample the parts"
                open(os.path.join(WORK, "ptm_cloth.osl"), "w").write(src)
                counts["osl lines"] = src.count("\n")
            else:
                for stage, flag in ((mx_gen.VERTEX_STAGE, "vert"), (mx_gen.PIXEL_STAGE, "frag")):
                    path = os.path.join(WORK, f"ptm_cloth.{flag}")
                    open(path, "w").write(shader.getSourceCode(stage))
                    r = subprocess.run(["glslangValidator", path], capture_output=True, text=True)
                    assert r.returncode == 0, f"glslangValidator {path}:\n{r.stdout}{r.stderr}"
                counts["glsl compiled"] = 2
# The README's MaterialX example is the node of example.mtlx.
readme = open(os.path.join(HERE, "..", "..", "README.md")).read()
block = readme.split("```xml\n", 1)[1].split("```", 1)[0]
example = open(os.path.join(HERE, "example.mtlx")).read()
assert all(line.strip() in example for line in block.splitlines()), "README MaterialX example differs from example.mtlx"
print(f"materialx: ND_ptm_occlusion_float validates; OSL and GLSL generated, GLSL compiled by glslangValidator ({counts})")
