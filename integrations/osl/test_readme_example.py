"""The OSL example of docs/pipeline.md (the shader group after `<!-- readme-osl -->`, in OSL's serialized
group syntax) against the shaders it names: every `shader NAME LAYER` is
integrations/osl/NAME.osl, every `param TYPE NAME VALUE... ;` before it is an input of that
shader with that type and as many values as the type has, every `connect a.X b.Y` joins an
output of an earlier layer to an input of a later one of the same type. No OSL compiler is needed (the
opt-in Blender test compiles and renders these shaders with Cycles' OSL).

    python test_readme_example.py
"""
import os
import re
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
README = os.path.join(HERE, "..", "..", "docs", "pipeline.md")
WIDTH = {"int": 1, "float": 1, "string": 1, "vector": 3, "point": 3, "normal": 3, "color": 3}


def signature(path):
    """{param: (type, is_output)} of the shader in an .osl file."""
    src = re.sub(r"//[^\n]*|/\*.*?\*/", "", open(path).read(), flags=re.S)
    m = re.search(r"\bshader\s+(\w+)\s*\((.*?)\)\s*\{", src, flags=re.S)
    assert m, f"{path}: no shader declaration"
    assert m.group(1) == os.path.basename(path)[:-4], f"{path}: shader is named {m.group(1)}"
    params, depth, cur = {}, 0, ""
    for ch in m.group(2) + ",":  # split on top-level commas (defaults may call vector(...))
        if ch == "," and depth == 0:
            p = re.match(r"\s*(output\s+)?(closure\s+color|\w+)\s+(\w+)", cur)
            assert p, f"{path}: cannot read parameter {cur.strip()!r}"
            params[p.group(3)] = (p.group(2).replace("closure ", "closure_").replace(" ", ""),
                                  bool(p.group(1)))
            cur = ""
            continue
        depth += ch == "("
        depth -= ch == ")"
        cur += ch
    return params


MARKERS = ("<!-- readme-osl -->", "<!-- readme-osl-learned -->")


def readme_group(readme=README, marker=MARKERS[0]):
    """The shader group of docs/pipeline.md after `marker`, checked against the shaders'
    signatures: a list of layers (shader, layer, {param: (type, [values])}) and of connections
    (src, out, dst, in)."""
    text = open(readme).read()
    assert f"{marker}\n```\n" in text, f"docs/pipeline.md has no {marker} block"
    block = text.split(f"{marker}\n```\n", 1)[1].split("```", 1)[0]
    layers, connections, pending = [], [], {}
    sigs = {}
    for stmt in (x.split() for x in block.split(";")):
        if not stmt:
            continue
        if stmt[0] == "param":  # param TYPE NAME VALUE... ; applies to the next shader
            ty, pname, values = stmt[1], stmt[2], stmt[3:]
            assert ty in WIDTH, f"docs/pipeline.md OSL example: unknown type {ty}"
            assert len(values) == WIDTH[ty], f"docs/pipeline.md: {pname} ({ty}) needs {WIDTH[ty]} values: {values}"
            if ty == "string":
                assert values[0].startswith('"') and values[0].endswith('"'), f"docs/pipeline.md: {pname} unquoted"
                values = [values[0][1:-1]]
            else:
                values = [(int if ty == "int" else float)(v) for v in values]
            pending[pname] = (ty, values)
        elif stmt[0] == "shader":
            name, layer = stmt[1], stmt[2]
            path = os.path.join(HERE, name + ".osl")
            assert os.path.exists(path), f"docs/pipeline.md OSL example: {name}.osl does not exist"
            sig = signature(path)
            for pname, (ty, _) in pending.items():
                assert pname in sig, f"docs/pipeline.md OSL example: {name} has no parameter {pname}"
                assert sig[pname] == (ty, False), f"docs/pipeline.md: {name}.{pname} is {sig[pname]}, not input {ty}"
            layers.append((name, layer, pending))
            sigs[layer], pending = sig, {}
        elif stmt[0] == "connect":
            (sl, sp), (dl, dp) = (w.split(".") for w in stmt[1:3])
            assert sl in sigs and dl in sigs, f"docs/pipeline.md: connect names an unknown layer: {stmt}"
            assert list(sigs).index(sl) < list(sigs).index(dl), f"docs/pipeline.md: {stmt} runs backwards"
            src, dst = sigs[sl].get(sp), sigs[dl].get(dp)
            assert src and src[1], f"docs/pipeline.md: {sl}.{sp} is not an output"
            assert dst and not dst[1], f"docs/pipeline.md: {dl}.{dp} is not an input"
            assert src[0] == dst[0], f"docs/pipeline.md: {stmt} joins {src[0]} to {dst[0]}"
            connections.append((sl, sp, dl, dp))
        else:
            sys.exit(f"docs/pipeline.md OSL example: cannot read {' '.join(stmt)!r}")
    assert not pending, f"docs/pipeline.md OSL example: params {list(pending)} apply to no shader"
    return layers, connections


def learned_shader_reads_what_the_layout_writes():
    """ptm_occlusion_learned.osl names the files the renderer layout writes (stem + ".c%d.exr",
    stem + ".basis%d.exr"), reads the basis parts bilinearly with clamp wrapping and no MIP
    filtering at the texel convention of docs/FORMAT.md, and counts ceil((k + 1)/4) coefficient
    parts and ceil(k/4) basis parts, checked as text (no OSL compiler here; the Blender test
    compiles and renders it)."""
    path = os.path.join(HERE, "ptm_occlusion_learned.osl")
    src = re.sub(r"//[^\n]*", "", open(path).read())
    for want in ('format(".c%d.exr"', 'format(".basis%d.exr"', '"wrap", "clamp"', '"interp", "linear"',
                 '"width", 0.0', "(terms + 4) / 4", "(terms + 3) / 4",
                 "(0.5 + (mu + 1) * 0.5 * (grid - 1)) / grid", "1 - (0.5 + (mv + 1) * 0.5 * (grid - 1)) / grid"):
        assert want in src, f"{path}: no {want!r}"
    # The part counts the shader computes, against the layout's rule for every k.
    for k in range(1, 17):
        assert (k + 4) // 4 == -(-(k + 1) // 4) and (k + 3) // 4 == -(-k // 4), k
    sig = signature(path)
    for name, ty in (("stem", "string"), ("terms", "int"), ("grid", "int"), ("light_dir", "vector")):
        assert sig.get(name) == (ty, False), f"{path}: {name} is {sig.get(name)}, not input {ty}"
    # The polynomial shader's parameters, but terms and grid for basis, link and uvmap (a
    # learned file is always logistic and hemispherical).
    poly = signature(os.path.join(HERE, "ptm_occlusion.osl"))
    for name in ("basis", "link", "uvmap"):
        del poly[name]
    assert sig == {**poly, "terms": ("int", False), "grid": ("int", False)}, (sig, poly)
    for name in ("K", "Visibility", "Coverage"):
        assert sig.get(name) == ("float", True), f"{path}: output {name} is {sig.get(name)}"


if __name__ == "__main__":
    for marker in MARKERS:
        layers, connections = readme_group(marker=marker)
        n = sum(len(p) for _, _, p in layers) + len(connections)
        print(f"osl: docs/pipeline.md {marker}: {len(layers)} layers, {n} parameters and connections match the shaders")
    learned_shader_reads_what_the_layout_writes()
    print("osl: ptm_occlusion_learned.osl reads the coefficient and basis parts as docs/FORMAT.md lays them out")
