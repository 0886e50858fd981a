"""Writes ptm_occlusion.mtlx: the MaterialX nodedef ND_ptm_occlusion_float and its
implementation NG_ptm_occlusion_float, a nodegraph of standard nodes only, reading an
occlusion PTM in the renderer layout (docs/FORMAT.md): part0..part2 are the files
w.ptm.c0.exr, w.ptm.c1.exr (, w.ptm.c2.exr for ptm11); basis 6 | 11, link 0 identity |
1 logistic, uvmap 0 projected | 1 hemispherical are the parts' ptm:basis, ptm:link, ptm:uv.
light_dir is the direction towards the key light in world space; out is K in [0, 1].

And ND_ptm_occlusion_learned_float (NG_ptm_occlusion_learned_float), the same for a learned
basis (ptm:basis = learnedN, always logistic and hemispherical): part0..part3 the coefficient
parts c0..c3 and basis0..basis3 the basis parts w.ptm.basis0.exr, … (⌈k/4⌉ of each are used;
leave the others empty, an image node of no file reads 0), grid the parts' ptm:learnedGrid.
p = Σᵢ dot(part i, basis part i) (channel by channel), the basis parts read bilinearly with clamp addressing at
uv = ((½ + (u+1)/2·(G−1))/G, (½ + (v+1)/2·(G−1))/G), K = σ(p).

    python make_mtlx.py [OUT.mtlx]     # default: ptm_occlusion.mtlx beside this script
"""
import os
import sys

import MaterialX as mx

PARTS = {
    6: [["u2", "u", "uv"], ["v", "v2", "1", "coverage"]],
    11: [["u3", "v3", "u2v2", "u2v"], ["uv2", "u2", "v2", "uv"], ["u", "v", "1", "coverage"]],
}
POWERS = {"1": (0, 0), "u": (1, 0), "v": (0, 1), "u2": (2, 0), "uv": (1, 1), "v2": (0, 2),
          "u3": (3, 0), "v3": (0, 3), "u2v": (2, 1), "uv2": (1, 2), "u2v2": (2, 2)}


LIB = mx.createDocument()
mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), LIB)
# Which standard nodedef a node of (category, type) with these inputs is; ifequal's selector is
# an integer (ND_ifequal_floatI).
CHOICE = {("ifequal", "float"): "ND_ifequal_floatI", ("extract", "float"): "ND_extract_color4",
          ("dotproduct", "float"): "ND_dotproduct_vector3",
          ("multiply", "vector3"): "ND_multiply_vector3FA"}
# Learned graph: the grid side as a float.
TO_FLOAT = "ND_convert_integer_float"
LEARNED_PARTS = 4  # k ≤ 16 terms: ⌈k/4⌉ ≤ 4 coefficient parts and basis parts in the sum


def nodedef_of(cat, typ, names, nd=None):
    if nd is not None:
        return LIB.getNodeDef(nd)
    if (cat, typ) in CHOICE:
        return LIB.getNodeDef(CHOICE[(cat, typ)])
    for nd in LIB.getMatchingNodeDefs(cat):
        have = {i.getName() for i in nd.getActiveInputs()}
        if nd.getType() == typ and set(names) <= have:
            return nd
    raise LookupError(f"no standard nodedef {cat} {typ} with inputs {names}")


class Graph:
    def __init__(self, ng):
        self.ng = ng
        self.n = 0

    def node(self, cat, typ, nd=None, **inputs):
        """A node of the standard nodedef of (cat, typ) with these inputs (or `nd`, by name)."""
        self.n += 1
        node = self.ng.addNode(cat, f"{cat}{self.n}", typ)
        nd = nodedef_of(cat, typ, inputs, nd)
        types = {i.getName(): i.getType() for i in nd.getActiveInputs()}
        for name, v in inputs.items():
            self.set(node, name, v, types[name])
        return node

    def set(self, node, name, v, typ):
        inp = node.addInput(name, typ)
        if isinstance(v, mx.Node):
            inp.setConnectedNode(v)
        elif isinstance(v, tuple) and v[0] == "if":
            inp.setInterfaceName(v[1])
        elif typ == "integer":
            inp.setValue(int(v), typ)
        elif typ == "string":
            inp.setValue(str(v), typ)
        else:
            inp.setValue(float(v), typ)

    def f(self, cat, *args):
        names = {1: ["in"], 2: ["in1", "in2"]}[len(args)]
        return self.node(cat, "float", **dict(zip(names, args)))

    def mul(self, *xs):
        out = xs[0]
        for x in xs[1:]:
            out = self.f("multiply", out, x)
        return out

    def add(self, *xs):
        out = xs[0]
        for x in xs[1:]:
            out = self.f("add", out, x)
        return out


def build():
    doc = mx.createDocument()
    nd = doc.addNodeDef("ND_ptm_occlusion_float", "float", "ptm_occlusion")
    nd.setNodeGroup("texture2d")
    nd.setDocString("Occluded fraction K of an occlusion PTM (renderer layout) for one light")
    for k in range(3):
        nd.addInput(f"part{k}", "filename").setValueString("")
    for name, v in (("basis", 6), ("link", 0), ("uvmap", 0)):
        nd.addInput(name, "integer").setValue(v, "integer")
    common_inputs(nd)

    ng = doc.addNodeGraph("NG_ptm_occlusion_float")
    ng.setNodeDefString("ND_ptm_occlusion_float")
    g = Graph(ng)
    iface = lambda name: ("if", name)  # noqa: E731
    imgs = [g.node("image", "color4", file=iface(f"part{k}"), texcoord=iface("texcoord"),
                   uaddressmode="periodic", vaddressmode="periodic", filtertype=iface("filtertype"))
            for k in range(3)]
    chan = lambda k, i: g.node("extract", "float", **{"in": imgs[k], "index": i})  # noqa: E731
    pu, pv, pz, s = light_frame(g, iface)
    mu = g.node("ifequal", "float", value1=iface("uvmap"), value2=1, in1=g.mul(pu, s), in2=pu)
    mv = g.node("ifequal", "float", value1=iface("uvmap"), value2=1, in1=g.mul(pv, s), in2=pv)
    polys = {}
    for basis, parts in PARTS.items():
        terms = []
        for k, slots in enumerate(parts):
            for i, m in enumerate(slots):
                if m == "coverage":
                    continue
                a, bb = POWERS[m]
                c = chan(k, i)
                terms.append(g.mul(c, *([mu] * a + [mv] * bb)) if a + bb else c)
        polys[basis] = g.add(*terms)
    p = g.node("ifequal", "float", value1=iface("basis"), value2=11, in1=polys[11], in2=polys[6])
    kval = g.node("ifequal", "float", value1=iface("link"), value2=1, in1=sigmoid(g, p), in2=p)
    k = g.node("clamp", "float", low=0.0, high=1.0, **{"in": kval})
    # At or below the horizon: K = 1.
    k = g.node("ifgreater", "float", value1=pz, value2=0.0, in1=k, in2=1.0)
    ng.addOutput("out", "float").setConnectedNode(k)
    build_learned(doc)
    return doc


def light_frame(g, iface):
    """(l·T, l·B, l·N, s) at the shading point, s the hemispherical map's scale: (u, v) =
    s·(l·T, l·B). T is the tangent made orthogonal to N, B = N × T."""
    n = g.node("normalize", "vector3", **{"in": iface("normal")})
    l = g.node("normalize", "vector3", **{"in": iface("light_dir")})
    traw = g.node("normalize", "vector3", **{"in": iface("tangent")})
    tn = g.node("multiply", "vector3", in1=n, in2=g.node("dotproduct", "float", in1=traw, in2=n))
    t = g.node("normalize", "vector3", **{"in": g.node("subtract", "vector3", in1=traw, in2=tn)})
    b = g.node("crossproduct", "vector3", in1=n, in2=t)
    pu = g.node("dotproduct", "float", in1=l, in2=t)
    pv = g.node("dotproduct", "float", in1=l, in2=b)
    pz = g.node("dotproduct", "float", in1=l, in2=n)
    # Hemispherical (u, v) = (θ/(π/2))/r · (pu, pv), θ = atan2(r, pz); r = 0 gives (0, 0).
    # No float constant but small integers: MaterialX writes floats with 6 significant digits
    # (π/2 became 1.5708) and its OSL and GLSL generators with 6 decimals (1e-20 became
    # 0.000000, so r = 0 divided 0 by 0). π/2 is atan2(1, 0), computed; r = 0 is a branch.
    r = g.f("sqrt", g.add(g.mul(pu, pu), g.mul(pv, pv)))
    theta = g.node("atan2", "float", iny=r, inx=pz)
    half_pi = g.node("atan2", "float", iny=1.0, inx=0.0)
    s = g.node("ifgreater", "float", value1=r, value2=0.0,
               in1=g.f("divide", g.f("divide", theta, half_pi), r), in2=0.0)
    return pu, pv, pz, s


def sigmoid(g, p):
    """σ(p) from e = exp(−|p|): 1/(1 + e) for p ≥ 0, e/(1 + e) otherwise."""
    e = g.f("exp", g.f("multiply", g.f("absval", p), -1.0))
    inv = g.f("divide", 1.0, g.f("add", e, 1.0))
    return g.node("ifgreatereq", "float", value1=p, value2=0.0, in1=inv, in2=g.mul(e, inv))


def common_inputs(nd):
    """The light direction, the geometric properties and the coefficient parts' filter."""
    nd.addInput("light_dir", "vector3").setValue(mx.Vector3(0, 0, 1), "vector3")
    nd.addInput("texcoord", "vector2").setAttribute("defaultgeomprop", "UV0")
    nd.addInput("normal", "vector3").setAttribute("defaultgeomprop", "Nworld")
    nd.addInput("tangent", "vector3").setAttribute("defaultgeomprop", "Tworld")
    nd.addInput("filtertype", "string").setValueString("linear")


def build_learned(doc):
    """ND_ptm_occlusion_learned_float and its nodegraph, in `doc`."""
    nd = doc.addNodeDef("ND_ptm_occlusion_learned_float", "float", "ptm_occlusion_learned")
    nd.setNodeGroup("texture2d")
    nd.setDocString("Occluded fraction K of an occlusion PTM with a learned basis (renderer layout: "
                    "coefficient parts and basis parts) for one light")
    for k in range(LEARNED_PARTS):
        nd.addInput(f"part{k}", "filename").setValueString("")
    for k in range(LEARNED_PARTS):
        nd.addInput(f"basis{k}", "filename").setValueString("")
    nd.addInput("grid", "integer").setValue(17, "integer")
    common_inputs(nd)

    ng = doc.addNodeGraph("NG_ptm_occlusion_learned_float")
    ng.setNodeDefString("ND_ptm_occlusion_learned_float")
    g = Graph(ng)
    iface = lambda name: ("if", name)  # noqa: E731
    imgs = [g.node("image", "color4", file=iface(f"part{k}"), texcoord=iface("texcoord"),
                   uaddressmode="periodic", vaddressmode="periodic", filtertype=iface("filtertype"))
            for k in range(LEARNED_PARTS)]
    pu, pv, pz, s = light_frame(g, iface)
    # The basis parts' uv of (u, v): (½ + (u + 1)/2·(G − 1))/G, MaterialX's v up (row 0 of a
    # basis part is v = +1, the image's top). Texel centres are at (i + ½)/G, so a bilinear
    # lookup with clamp addressing is the table's bilinear read, clamped at the edge.
    grid = g.node("convert", "float", nd=TO_FLOAT, **{"in": iface("grid")})
    span = g.f("subtract", grid, 1.0)

    def coord(m):
        return g.f("divide", g.f("add", g.mul(g.f("add", m, 1.0), 0.5, span), 0.5), grid)

    st = g.node("combine2", "vector2", in1=coord(g.mul(pu, s)), in2=coord(g.mul(pv, s)))
    # Σ over parts and channels of coefficient × basis value (the 4-vector dot products; channel
    # by channel with `extract`, since MaterialX implements color4 → vector4 as a nodegraph).
    terms = []
    for k in range(LEARNED_PARTS):
        table = g.node("image", "color4", file=iface(f"basis{k}"), texcoord=st, uaddressmode="clamp",
                       vaddressmode="clamp", filtertype="linear")
        for c in range(4):
            terms.append(g.mul(g.node("extract", "float", **{"in": imgs[k], "index": c}),
                               g.node("extract", "float", **{"in": table, "index": c})))
    p = g.add(*terms)
    k = g.node("clamp", "float", low=0.0, high=1.0, **{"in": sigmoid(g, p)})
    # At or below the horizon: K = 1.
    k = g.node("ifgreater", "float", value1=pz, value2=0.0, in1=k, in2=1.0)
    ng.addOutput("out", "float").setConnectedNode(k)


if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), "ptm_occlusion.mtlx")
    doc = build()
    mx.writeToXmlFile(doc, out)
    print(f"wrote {out}")
