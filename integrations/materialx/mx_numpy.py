"""A numeric evaluator of MaterialX nodes, independent of MaterialX's code generators: it walks a
node's implementation nodegraph through the MaterialX Python API and evaluates every standard
node with numpy (float64), over an array of shading points at once. What test_materialx.py
checks ND_ptm_occlusion_float's K with (against Rust `Ptm::eval`).

Only the standard nodes listed in OPS are known, each with the semantics of the MaterialX 1.39
specification (and of its genosl / genglsl implementations); a node of any other category, an
input this evaluator does not implement (an image `layer`, a `framerange`, a colour space, the
`cubic` filter) or a geometric property other than UV0, Nworld and Tworld raises
`Unsupported`: it never guesses.

    ev = Evaluator(geom={"UV0": uv, "Nworld": n, "Tworld": t}, root=dir_of_files)
    k = ev.node(doc.getNode("K"))      # ndarray (points,) for a float output

Values: a float or integer is an array of shape (points,) or a scalar; a vector/colour of size
k is (points, k) or (k,); strings and filenames are Python strings (uniform).
"""
import os

import MaterialX as mx
import numpy as np
import OpenImageIO as oiio

SIZES = {"float": 1, "integer": 1, "boolean": 1, "vector2": 2, "vector3": 3, "vector4": 4,
         "color3": 3, "color4": 4}


class Unsupported(Exception):
    """A node, input or property the evaluator does not implement (the check must fail)."""


def _vec(x, n):
    """Promotes a float value (scalar or (points,)) to a vector of n lanes."""
    x = np.asarray(x, dtype=np.float64)
    return np.repeat(x[..., None], n, axis=-1)


def _normalize(v):
    v = np.asarray(v, dtype=np.float64)
    # genosl normalize() and GLSL normalize(): v / |v| (0 / 0 is left as it falls: NaN).
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# Standard nodes by category: f(inputs by name) -> value. The float/vector variants of the math
# nodes (e.g. ND_multiply_vector3FA) reach them with the float input already promoted.
OPS = {
    "add": lambda i: i["in1"] + i["in2"],
    "subtract": lambda i: i["in1"] - i["in2"],
    "multiply": lambda i: i["in1"] * i["in2"],
    "divide": lambda i: i["in1"] / i["in2"],
    "max": lambda i: np.maximum(i["in1"], i["in2"]),
    "min": lambda i: np.minimum(i["in1"], i["in2"]),
    "absval": lambda i: np.abs(i["in"]),
    "sqrt": lambda i: np.sqrt(i["in"]),
    "exp": lambda i: np.exp(i["in"]),
    "atan2": lambda i: np.arctan2(i["iny"], i["inx"]),
    "clamp": lambda i: np.minimum(np.maximum(i["in"], i["low"]), i["high"]),
    "normalize": lambda i: _normalize(i["in"]),
    "dotproduct": lambda i: np.sum(np.asarray(i["in1"]) * np.asarray(i["in2"]), axis=-1),
    "crossproduct": lambda i: np.cross(i["in1"], i["in2"]),
    "extract": lambda i: np.asarray(i["in"])[..., int(i["index"])],
    "combine2": lambda i: np.stack(np.broadcast_arrays(np.asarray(i["in1"], dtype=np.float64),
                                                       np.asarray(i["in2"], dtype=np.float64)), axis=-1),
    # Only the conversions in CONVERTS, which keep the value as it is.
    "convert": lambda i: np.asarray(i["in"], dtype=np.float64),
}
# The convert nodedefs OPS["convert"] implements: integer → float. Others (a float promoted to a
# colour, a colour3 widened to four lanes with alpha 1, …) change the lanes and are refused.
CONVERTS = {"ND_convert_integer_float"}
# Nodes whose float inputs are not promoted to their vector output's lanes.
NO_PROMOTION = {"extract", "combine2", "convert"}
# The conditionals: in1 where value1 <op> value2, else in2.
IFS = {"ifgreater": np.greater, "ifgreatereq": np.greater_equal, "ifequal": np.equal}


def _constant(inp):
    """The value of an unconnected input (or nodedef default) as a number/array/string."""
    typ = inp.getType()
    s = inp.getValueString()
    if typ in ("string", "filename"):
        return s
    if typ not in SIZES:
        raise Unsupported(f"{inp.getNamePath()}: input type {typ}")
    if s == "":
        raise Unsupported(f"{inp.getNamePath()}: no value")
    v = [float(x) for x in s.split(",")]
    if typ == "integer":
        return int(v[0])
    if typ == "boolean":
        return s.strip() == "true"
    return np.float64(v[0]) if len(v) == 1 else np.array(v, dtype=np.float64)


class Evaluator:
    """Evaluates nodes at many shading points. `geom` maps the geometric properties a nodedef
    may default to (UV0: (points, 2) with MaterialX's convention, (0, 0) = the image's
    bottom-left; Nworld, Tworld: (points, 3)) to arrays; file names resolve against `root`."""

    def __init__(self, geom, root="."):
        self.geom = geom
        self.root = root
        self.images = {}
        self.used = set()  # nodedef names evaluated (the test reports them)

    # -- graph walking ---------------------------------------------------------------------
    def node(self, node, scope=None, output="", cache=None):
        """Value of `node` (a Node in a document or nodegraph); `scope` maps the interface
        names of the enclosing nodegraph to values, `cache` memoises that graph's nodes."""
        if cache is not None and node.getName() in cache:
            return cache[node.getName()]
        nd = node.getNodeDef()
        if nd is None:
            raise Unsupported(f"{node.getNamePath()}: no nodedef matches ({node.getCategory()})")
        outs = nd.getActiveOutputs()
        if len(outs) != 1 or output not in ("", outs[0].getName()):
            raise Unsupported(f"{node.getNamePath()}: multi-output nodes ({nd.getName()})")
        for inp in node.getInputs():
            if nd.getActiveInput(inp.getName()) is None:
                raise Unsupported(f"{inp.getNamePath()}: not an input of {nd.getName()}")
        inputs = {ndi.getName(): self._input(node, ndi, node.getInput(ndi.getName()), scope, cache)
                  for ndi in nd.getActiveInputs()}
        impl = nd.getImplementation()
        if impl is not None and impl.isA(mx.NodeGraph):
            val = self._graph(impl, inputs)
        else:
            val = self._standard(node, nd, inputs)
        if cache is not None:
            cache[node.getName()] = val
        return val

    def _standard(self, node, nd, inputs):
        self.used.add(nd.getName())
        cat = node.getCategory()
        if cat == "image":
            return self._image(node, inputs)
        if cat not in OPS and cat not in IFS:
            raise Unsupported(f"{node.getNamePath()}: no numpy evaluation of {nd.getName()} ({cat})")
        if cat == "convert" and nd.getName() not in CONVERTS:
            raise Unsupported(f"{node.getNamePath()}: no numpy evaluation of {nd.getName()}")
        out_size = SIZES.get(nd.getType(), 0)
        if out_size > 1 and cat not in NO_PROMOTION:  # a float operand of a vector node acts per lane
            for ndi in nd.getActiveInputs():
                if ndi.getType() == "float" and ndi.getName() not in ("value1", "value2"):
                    inputs[ndi.getName()] = _vec(inputs[ndi.getName()], out_size)
        if cat in IFS:
            cond = np.asarray(IFS[cat](inputs["value1"], inputs["value2"]))
            return np.where(cond[..., None] if out_size > 1 else cond, inputs["in1"], inputs["in2"])
        # Shading languages compute both branches of a conditional (mx_ternary, ?:): a 0 / 0
        # in the branch not taken is no error, here either; a NaN that reaches K is (the test).
        with np.errstate(divide="ignore", invalid="ignore"):
            return OPS[cat](inputs)

    def _input(self, node, ndi, inp, scope, cache):
        if inp is not None:
            if inp.getColorSpace():
                raise Unsupported(f"{inp.getNamePath()}: colorspace {inp.getColorSpace()}")
            if inp.getConnectedNode() is not None:
                return self.node(inp.getConnectedNode(), scope, inp.getOutputString(), cache)
            if inp.hasInterfaceName():
                if scope is None or inp.getInterfaceName() not in scope:
                    raise Unsupported(f"{inp.getNamePath()}: interface {inp.getInterfaceName()} unknown")
                return scope[inp.getInterfaceName()]
            if inp.getNodeGraphString() or inp.getOutputString() or inp.getNodeName():
                raise Unsupported(f"{inp.getNamePath()}: connection to a nodegraph output")
            if inp.hasValueString():
                return _constant(inp)
        if ndi.hasAttribute("defaultgeomprop"):
            gp = ndi.getAttribute("defaultgeomprop")
            if gp not in self.geom:
                raise Unsupported(f"{node.getNamePath()}.{ndi.getName()}: geomprop {gp}")
            return self.geom[gp]
        return _constant(ndi)

    def _graph(self, ng, scope):
        outs = ng.getOutputs()
        if len(outs) != 1 or outs[0].getConnectedNode() is None:
            raise Unsupported(f"{ng.getName()}: not one output connected to a node")
        # Nodes inside a nodegraph are shared (a DAG): each is evaluated once per instance.
        return self.node(outs[0].getConnectedNode(), scope, "", {})

    # -- the image node ----------------------------------------------------------------------
    def _texels(self, path):
        if path not in self.images:
            inp = oiio.ImageInput.open(path)
            if inp is None:
                raise FileNotFoundError(f"{path}: {oiio.geterror()}")
            spec = inp.spec()
            data = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, "float"), dtype=np.float64)
            inp.close()
            if data.ndim == 2:
                data = data[:, :, None]
            h, w, c = data.shape
            rgba = np.zeros((h, w, 4))
            rgba[:, :, 3] = 1.0  # texture systems read alpha = 1 from an image without alpha
            if c == 1:
                rgba[:, :, :3] = data[:, :, :1]
            else:
                rgba[:, :, :min(c, 4)] = data[:, :, :4]
            self.images[path] = rgba
        return self.images[path]

    def _image(self, node, i):
        if node.getType() != "color4":
            raise Unsupported(f"{node.getNamePath()}: image of type {node.getType()}")
        for name, want in (("layer", ""), ("framerange", ""), ("frameoffset", 0)):
            if i[name] != want:
                raise Unsupported(f"{node.getNamePath()}: {name} = {i[name]!r}")
        uv = np.asarray(i["texcoord"], dtype=np.float64)
        default = np.broadcast_to(np.asarray(i["default"], dtype=np.float64), uv.shape[:-1] + (4,))
        if i["file"] == "":
            return default.copy()
        tex = self._texels(os.path.join(self.root, i["file"]))
        h, w, _ = tex.shape
        # MaterialX (0, 0) is the image's bottom-left; row 0 of the file is its top (OSL's and
        # OIIO's t = 0: MaterialX's OSL flips v only with GenOptions.fileTextureVerticalFlip).
        # Texel centres at +0.5.
        x = uv[..., 0] * w - 0.5
        y = (1.0 - uv[..., 1]) * h - 0.5
        outside = np.zeros(x.shape, dtype=bool)
        for mode, coord in ((i["uaddressmode"], uv[..., 0]), (i["vaddressmode"], uv[..., 1])):
            if mode == "constant":
                outside |= (coord < 0) | (coord > 1)
            elif mode not in ("periodic", "clamp", "mirror"):
                raise Unsupported(f"{node.getNamePath()}: address mode {mode!r}")

        def wrap(k, n, mode):
            if mode == "periodic":
                return np.mod(k, n)
            if mode == "mirror":
                k = np.mod(k, 2 * n)
                return np.where(k >= n, 2 * n - 1 - k, k)
            return np.clip(k, 0, n - 1)  # clamp, and constant inside [0, 1]

        um, vm = i["uaddressmode"], i["vaddressmode"]
        ft = i["filtertype"]
        if ft == "closest":
            c = wrap(np.floor(x + 0.5).astype(np.int64), w, um)
            r = wrap(np.floor(y + 0.5).astype(np.int64), h, vm)
            out = tex[r, c]
        elif ft == "linear":
            x0, y0 = np.floor(x), np.floor(y)
            fx, fy = (x - x0)[..., None], (y - y0)[..., None]
            c0, c1 = wrap(x0.astype(np.int64), w, um), wrap(x0.astype(np.int64) + 1, w, um)
            r0, r1 = wrap(y0.astype(np.int64), h, vm), wrap(y0.astype(np.int64) + 1, h, vm)
            out = ((1 - fy) * ((1 - fx) * tex[r0, c0] + fx * tex[r0, c1])
                   + fy * ((1 - fx) * tex[r1, c0] + fx * tex[r1, c1]))
        else:
            raise Unsupported(f"{node.getNamePath()}: filtertype {ft!r}")
        return np.where(outside[..., None], default, out)
