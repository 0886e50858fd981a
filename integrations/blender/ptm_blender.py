"""Build Blender materials from an occlusion PTM in the renderer layout (docs/FORMAT.md).

Two ways to evaluate K, both taking the key light's direction from a named light object
through drivers (a sun's +Z axis; for a point, spot or area light, from the shading point
towards the light's position):

- ``mode="osl"``: a Script node running integrations/osl/ptm_occlusion.osl, or
  ptm_occlusion_learned.osl for a learned basis (Cycles, CPU, with Open Shading Language
  enabled; ``build_material`` switches it on).
- ``mode="nodes"``: a node group made of Blender's own Image Texture, Separate Color, Vector
  Math and Math nodes, so EEVEE and GPU Cycles work too; for a learned basis it also reads the
  basis parts (``w.ptm.basis0.exr``, …) at the light's (u, v).

A learned file's basis parts are checked before anything is built (integrations/osl/
ptm_params.py: their size, finite values, term count and agreement with the header's table);
a bad one raises ``ValueError`` naming the file and the figures.

What K darkens (``output=``):

- ``"lit"`` (default): a Principled BSDF left as it is, plus a shader AOV ``ptm_k`` = K, and
  the scene set up by ``occlude_key_light``: the key light in its own Cycles light group and a
  compositor that subtracts the key light's pass × K from the image. Only the key light is
  occluded: the world, fill lights and emitters are not. Cycles only (light groups).
- ``"multiply"``: base colour × (1 - K). Any engine (EEVEE too), but K then darkens everything
  the surface reflects, the world and fill lights as well as the key: exact only when the key
  light is the only light.
- ``"k"``: emits K itself (what the tests render).

Use as a script (a whole scene rendered in one command: ``ptm_scene.py`` beside this file)::

    import sys; sys.path.insert(0, "integrations/blender")
    import bpy, ptm_blender
    bpy.ops.mesh.primitive_plane_add(size=2)
    plane = bpy.context.active_object
    plane.data.materials.append(ptm_blender.build_material("w.ptm.c0.exr", light="Light"))

On a mesh of your own, one call sets up the whole material (PTM, the bake's normal map and AO,
the key light's occlusion) and assigns it: ``ptm_blender.apply_material(obj, "w.ptm.c0.exr",
light="Light", repeat=8)``.

Blender's own Python has no OpenEXR module: the header is read here by hand (``read_header``).
"""

import math
import os
import struct
import sys

import bpy

def _find_oslquery():
    """Blender as a Python module (PyPI `bpy`) keeps Cycles' `oslquery` in its own bundled
    site-packages, which is not on sys.path: add it so OSL script nodes compile."""
    import glob
    import sys
    try:
        import oslquery  # noqa: F401
        return
    except ImportError:
        pass
    root = bpy.utils.resource_path("LOCAL")  # …/bpy/5.0
    for d in glob.glob(os.path.join(root, "python", "lib", "python3*", "site-packages")):
        if os.path.isdir(os.path.join(d, "oslquery")) and d not in sys.path:
            sys.path.append(d)


_find_oslquery()

HERE = os.path.dirname(os.path.abspath(__file__))
OSL_SHADER = os.path.join(HERE, "..", "osl", "ptm_occlusion.osl")
OSL_LEARNED = os.path.join(HERE, "..", "osl", "ptm_occlusion_learned.osl")
sys.path.insert(0, os.path.join(HERE, "..", "osl"))
import ptm_params  # noqa: E402  the parts' reader (standard library only), shared with OSL users

# Slots of the renderer layout: (part, channel) of each monomial, in basis order.
PARTS = {
    "ptm6": [["u2", "u", "uv"], ["v", "v2", "1", "coverage"]],
    "ptm11": [
        ["u3", "v3", "u2v2", "u2v"],
        ["uv2", "u2", "v2", "uv"],
        ["u", "v", "1", "coverage"],
    ],
}
POWERS = {
    "1": (0, 0), "u": (1, 0), "v": (0, 1), "u2": (2, 0), "uv": (1, 1), "v2": (0, 2),
    "u3": (3, 0), "v3": (0, 3), "u2v": (2, 1), "uv2": (1, 2), "u2v2": (2, 2),
}


def read_header(path):
    """String, int and double attributes of an OpenEXR file's (first) header."""
    out = {}
    with open(path, "rb") as f:
        if f.read(4) != b"\x76\x2f\x31\x01":
            raise ValueError(f"{path}: not an OpenEXR file")
        f.read(4)
        data = f.read(1 << 20)
    pos = 0
    while data[pos] != 0:
        name_end = data.index(b"\0", pos)
        type_end = data.index(b"\0", name_end + 1)
        name = data[pos:name_end].decode("utf-8", "replace")
        typ = data[name_end + 1:type_end].decode()
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        value = data[type_end + 5:type_end + 5 + size]
        if typ == "string":
            out[name] = value.decode("utf-8", "replace")
        elif typ == "int":
            out[name] = struct.unpack("<i", value)[0]
        elif typ == "double":
            out[name] = struct.unpack("<d", value)[0]
        pos = type_end + 5 + size
    return out


def stem_of(path):
    """`w.ptm.c0.exr` / `w.ptm.basis0.exr` / `w.ptm.exr` → `w.ptm`."""
    return ptm_params.stem_of(path)


def ptm_info(path):
    """(stem, basis, link, uv) of the renderer-layout PTM that `path` names. A learned basis
    (`learnedN`) has its basis parts checked (ptm_params.learned_params: size, finite values,
    the term count, the header's table); `learned(path)` gives its terms and grid."""
    stem = stem_of(path)
    h = read_header(stem + ".c0.exr")
    if h.get("ptm:layout") != "rgba/1":
        raise ValueError(f"{stem}.c0.exr: not a PTM in the renderer layout (ptm fit --layout rgba)")
    basis, link, uv = h["ptm:basis"], h.get("ptm:link", "identity"), h.get("ptm:uv", "projected")
    if basis.startswith("learned"):
        ptm_params.learned_params(stem + ".c0.exr")
        if (link, uv) != ("logistic", "hemispherical"):
            raise ValueError(f"{stem}.c0.exr: a learned basis is logistic and hemispherical, not {link}, {uv}")
        return stem, basis, link, uv
    if basis not in PARTS or link not in ("identity", "logistic") or uv not in ("projected", "hemispherical"):
        raise ValueError(f"{stem}.c0.exr: unknown basis, link or uv: {basis}, {link}, {uv}")
    return stem, basis, link, uv


def _drive(socket, index, light, data_path):
    """Driver: socket.default_value[index] (None: the whole value) = `data_path` of the light
    object, an RNA path into it."""
    fc = socket.driver_add("default_value") if index is None else socket.driver_add("default_value", index)
    d = fc.driver
    d.type = "SCRIPTED"
    var = d.variables.new()
    var.name = "a"
    var.type = "SINGLE_PROP"
    var.targets[0].id_type = "OBJECT"
    var.targets[0].id = light
    var.targets[0].data_path = data_path
    d.expression = "a"


def _drive_light_dir(socket, light):
    """Drivers: socket.default_value = the light object's +Z axis (towards a sun) in world space."""
    for i in range(3):
        # RNA paths index the matrix as stored, column first: [2][i] is row i of the Z axis.
        _drive(socket, i, light, f"matrix_world[2][{i}]")


def _connect_light(tree, light_in, light):
    """Feeds `light_in` the direction from the shading point towards the key light: a sun's +Z
    axis (the same everywhere), else (point, spot, area) towards the light's position from the
    shading point, in world space."""
    if light.data.type == "SUN":
        light_in.default_value = light_direction(light)
        _drive_light_dir(light_in, light)
        return
    pos = tree.nodes.new("ShaderNodeCombineXYZ")  # the light's world position
    for i, c in enumerate(light.matrix_world.translation):
        pos.inputs[i].default_value = c
        _drive(pos.inputs[i], None, light, f"matrix_world[3][{i}]")
    geo = tree.nodes.new("ShaderNodeNewGeometry")
    sub = tree.nodes.new("ShaderNodeVectorMath")
    sub.operation = "SUBTRACT"
    tree.links.new(pos.outputs[0], sub.inputs[0])
    tree.links.new(geo.outputs["Position"], sub.inputs[1])
    tree.links.new(sub.outputs["Vector"], light_in)


def light_direction(light):
    m = light.matrix_world
    return (m[0][2], m[1][2], m[2][2])


class _G:
    """Small expression builder over a node tree's Math / Vector Math nodes."""

    def __init__(self, tree):
        self.tree = tree
        self.x = 0

    def node(self, kind, **props):
        n = self.tree.nodes.new(kind)
        for k, v in props.items():
            setattr(n, k, v)
        self.x += 1
        n.location = (200 * (self.x // 20), -120 * (self.x % 20))
        return n

    def _in(self, n, i, a):
        if isinstance(a, (int, float)):
            n.inputs[i].default_value = a
        else:
            self.tree.links.new(a, n.inputs[i])

    def math(self, op, a, b=0.0, clamp=False):
        n = self.node("ShaderNodeMath", operation=op, use_clamp=clamp)
        self._in(n, 0, a)
        self._in(n, 1, b)
        return n.outputs[0]

    def vmath(self, op, a, b):
        n = self.node("ShaderNodeVectorMath", operation=op)
        self.tree.links.new(a, n.inputs[0])
        self.tree.links.new(b, n.inputs[1])
        return n.outputs["Value"] if op == "DOT_PRODUCT" else n.outputs["Vector"]

    def mul(self, *xs):
        out = xs[0]
        for x in xs[1:]:
            out = self.math("MULTIPLY", out, x)
        return out

    def add(self, *xs):
        out = xs[0]
        for x in xs[1:]:
            out = self.math("ADD", out, x)
        return out


def _image_node(g, path, interpolation, extension):
    img = bpy.data.images.load(path, check_existing=True)
    img.colorspace_settings.name = "Non-Color"
    img.alpha_mode = "CHANNEL_PACKED"
    return g.node("ShaderNodeTexImage", image=img, interpolation=interpolation, extension=extension)


def _rgba(g, tex):
    """The R, G, B, A sockets of an Image Texture node."""
    sep = g.node("ShaderNodeSeparateColor")
    g.tree.links.new(tex.outputs["Color"], sep.inputs[0])
    return [sep.outputs[i] for i in range(3)] + [tex.outputs["Alpha"]]


def _light_frame(g, gin):
    """(l·T, l·B, l·N) with T the UV tangent made orthogonal to N, B = N × T."""
    geo = g.node("ShaderNodeNewGeometry")
    tan = g.node("ShaderNodeTangent", direction_type="UV_MAP")
    n = geo.outputs["Normal"]
    lnorm = g.vmath("NORMALIZE", gin.outputs["Light"], gin.outputs["Light"])
    t_raw = tan.outputs["Tangent"]
    proj = g.vmath("DOT_PRODUCT", t_raw, n)
    scale_n = g.node("ShaderNodeVectorMath", operation="SCALE")
    g.tree.links.new(n, scale_n.inputs[0])
    g.tree.links.new(proj, scale_n.inputs["Scale"])
    t = g.vmath("NORMALIZE", g.vmath("SUBTRACT", t_raw, scale_n.outputs["Vector"]), n)
    b = g.vmath("CROSS_PRODUCT", n, t)
    return g.vmath("DOT_PRODUCT", lnorm, t), g.vmath("DOT_PRODUCT", lnorm, b), g.vmath("DOT_PRODUCT", lnorm, n)


def _sigmoid(g, p):
    e = g.math("EXPONENT", g.math("MULTIPLY", g.math("ABSOLUTE", p), -1.0))
    sig = g.math("DIVIDE", 1.0, g.math("ADD", e, 1.0))
    pos = g.math("GREATER_THAN", p, -1e-30)  # 1 where p >= 0
    return g.add(g.mul(pos, sig), g.mul(g.math("SUBTRACT", 1.0, pos), e, sig))


def learned_group(stem, interpolation="Linear"):
    """The node group of `occlusion_group` for a learned basis: K = σ(Σᵢ dot(cᵢ, basisᵢ)), the
    coefficient parts cᵢ read at the UV like any part, the basis parts at the light's
    hemispherical (u, v), uv = ½ + (u, v)·(G − 1)/(2G) (the texel convention of
    docs/FORMAT.md: (½ + (u + 1)/2·(G − 1))/G), Linear and Extend (clamp), whatever
    `interpolation` the coefficients get. The basis parts are checked first (ptm_params)."""
    p = ptm_params.learned_params(stem + ".c0.exr")
    name = f"PTM {os.path.basename(stem)} {p['basis']} {interpolation}"
    if name in bpy.data.node_groups:
        return bpy.data.node_groups[name]
    tree = bpy.data.node_groups.new(name, "ShaderNodeTree")
    tree.interface.new_socket("Vector", in_out="INPUT", socket_type="NodeSocketVector")
    tree.interface.new_socket("Light", in_out="INPUT", socket_type="NodeSocketVector")
    for out in ("K", "Visibility", "Coverage"):
        tree.interface.new_socket(out, in_out="OUTPUT", socket_type="NodeSocketFloat")
    g = _G(tree)
    gin = g.node("NodeGroupInput")
    gout = g.node("NodeGroupOutput")
    coeffs = []
    for part in p["parts"]:
        tex = _image_node(g, part, interpolation, "REPEAT")
        tree.links.new(gin.outputs["Vector"], tex.inputs["Vector"])
        coeffs.append(_rgba(g, tex))
    pu, pv, pz = _light_frame(g, gin)
    r = g.math("SQRT", g.add(g.mul(pu, pu), g.mul(pv, pv)))
    theta = g.math("ARCTAN2", r, pz)
    s = g.math("DIVIDE", g.math("DIVIDE", theta, math.pi / 2), r)  # Blender: x / 0 = 0
    step = (p["grid"] - 1) / (2 * p["grid"])
    st = g.node("ShaderNodeCombineXYZ")
    for i, m in enumerate((pu, pv)):
        tree.links.new(g.math("ADD", g.math("MULTIPLY", g.mul(m, s), step), 0.5), st.inputs[i])
    terms = []
    for i, table in enumerate(p["basis_parts"]):
        tex = _image_node(g, table, "Linear", "EXTEND")
        tree.links.new(st.outputs["Vector"], tex.inputs["Vector"])
        terms += [g.mul(c, b) for c, b in zip(coeffs[i], _rgba(g, tex))]
    k = _sigmoid(g, g.add(*terms))
    below = g.math("LESS_THAN", pz, 1e-12)  # at or below the horizon: K = 1
    k = g.math("MAXIMUM", g.math("ADD", k, 0.0, clamp=True), below)
    tree.links.new(k, gout.inputs["K"])
    tree.links.new(g.math("SUBTRACT", 1.0, k), gout.inputs["Visibility"])
    tree.links.new(coeffs[-1][3], gout.inputs["Coverage"])
    return tree


def occlusion_group(stem, basis, link, uv, interpolation="Linear"):
    """A node group (inputs Vector = UV, Light; outputs K, Visibility, Coverage) of Blender's
    own nodes evaluating K = clamp(link(p(u, v)), 0, 1) from the PTM's parts (a learned basis:
    `learned_group`)."""
    if basis.startswith("learned"):
        return learned_group(stem, interpolation)
    name = f"PTM {os.path.basename(stem)} {basis} {link} {uv} {interpolation}"
    if name in bpy.data.node_groups:
        return bpy.data.node_groups[name]
    tree = bpy.data.node_groups.new(name, "ShaderNodeTree")
    tree.interface.new_socket("Vector", in_out="INPUT", socket_type="NodeSocketVector")
    tree.interface.new_socket("Light", in_out="INPUT", socket_type="NodeSocketVector")
    for out in ("K", "Visibility", "Coverage"):
        tree.interface.new_socket(out, in_out="OUTPUT", socket_type="NodeSocketFloat")
    g = _G(tree)
    gin = g.node("NodeGroupInput")
    gout = g.node("NodeGroupOutput")
    coeff = {}
    for k, slots in enumerate(PARTS[basis]):
        tex = _image_node(g, f"{stem}.c{k}.exr", interpolation, "REPEAT")
        tree.links.new(gin.outputs["Vector"], tex.inputs["Vector"])
        for m, socket in zip(slots, _rgba(g, tex)):
            coeff[m] = socket
    pu, pv, pz = _light_frame(g, gin)
    if uv == "hemispherical":
        r = g.math("SQRT", g.add(g.mul(pu, pu), g.mul(pv, pv)))
        theta = g.math("ARCTAN2", r, pz)
        s = g.math("DIVIDE", g.math("DIVIDE", theta, math.pi / 2), r)  # Blender: x / 0 = 0
        mu, mv = g.mul(pu, s), g.mul(pv, s)
    else:
        mu, mv = pu, pv
    terms = []
    for slots in PARTS[basis]:
        for m in slots:
            if m == "coverage":
                continue
            a, bb = POWERS[m]
            terms.append(g.mul(coeff[m], *([mu] * a + [mv] * bb)) if a + bb else coeff[m])
    p = g.add(*terms)
    kval = _sigmoid(g, p) if link == "logistic" else p
    below = g.math("LESS_THAN", pz, 1e-12)  # at or below the horizon: K = 1
    k = g.math("MAXIMUM", g.math("ADD", kval, 0.0, clamp=True), below)
    tree.links.new(k, gout.inputs["K"])
    tree.links.new(g.math("SUBTRACT", 1.0, k), gout.inputs["Visibility"])
    tree.links.new(coeff["coverage"], gout.inputs["Coverage"])
    return tree


AOV = "ptm_k"
AMBIENT_AOV = "ptm_ambient"
KEY_GROUP = "ptm_key"
COMPOSITOR = "PTM key-light occlusion"


def _light_object(light):
    if not isinstance(light, str):
        return light
    obj = bpy.data.objects.get(light)
    if obj is None or obj.type != "LIGHT":
        lights = sorted(o.name for o in bpy.data.objects if o.type == "LIGHT")
        raise KeyError(f"key light {light!r}: no light object of that name in this file "
                       f"(lights here: {', '.join(lights) or 'none'}); pass light= one of them")
    return obj


def companion_maps(path):
    """The companion maps `ptm bake --maps --maps-png` wrote beside the PTM at `path`
    (`w.ptm.c0.exr` → `w.normal.png`, `w.ao.png`): {"normal": file, "ao": file} for those
    that exist."""
    base = stem_of(path)
    base = base[:-4] if base.endswith(".ptm") else base
    found = {}
    for name in ("normal", "ao"):
        f = f"{base}.{name}.png"
        if os.path.exists(f):
            found[name] = f
    return found


def occlude_key_light(light, scene=None, denoise=None, ambient=False):
    """Confines the PTM's occlusion to the key light: `light` (object or name) goes into the
    Cycles light group ``ptm_key``; every view layer gets the value AOV ``ptm_k`` (written by
    the materials of ``build_material(output="lit")``; 0 elsewhere) and the light-group pass;
    the compositor outputs Image − Combined_ptm_key × ptm_k, i.e. the key light's contribution
    × (1 − K) plus everything else untouched. Idempotent. Switches the scene to Cycles.

    `denoise` (default: the scene's Cycles denoising setting) moves denoising after the
    subtraction (render denoising off, a Denoise node with the albedo and normal passes at the
    end), since the light-group pass is never denoised: subtracting a noisy pass from a denoised
    image would put the noise back into the shadows.

    `ambient=True` (``build_material`` sets it when it applies an AO map) also multiplies the
    rest of the light, everything but the key, by the AO map: the value AOV ``ptm_ambient`` =
    1 − AO, and the output is Image − key × ptm_k − (Image − key) × ptm_ambient. AO stands for
    the occlusion of ambient light by detail below the mesh (glTF's occlusion texture is defined
    the same way: indirect light only). Once on, it stays on for the scene.

    Limits: the product is taken per pixel on the camera's first hit, so the key light seen in
    reflections and refractions and its indirect bounces are darkened by the K of the pixel
    they end up in, not of the surface they left; a pixel straddling two surfaces gets the
    product of their averages. Needs Blender 5.0's compositor node groups (tested with 5.0.1)."""
    scene = scene or bpy.context.scene
    light = _light_object(light)
    if not hasattr(scene, "compositing_node_group"):
        raise RuntimeError(f"Blender {bpy.app.version_string}: occlude_key_light needs Blender 5.0 "
                           "(compositor node groups); use build_material(output=\"multiply\") instead")
    scene.render.engine = "CYCLES"
    ambient = ambient or bool(scene.get("ptm_ambient", False))
    scene["ptm_ambient"] = ambient
    if denoise is None:
        denoise = scene.cycles.use_denoising
    scene.cycles.use_denoising = False
    light.lightgroup = KEY_GROUP
    for vl in scene.view_layers:
        if KEY_GROUP not in vl.lightgroups:
            vl.lightgroups.add(name=KEY_GROUP)
        for name in (AOV, AMBIENT_AOV) if ambient else (AOV,):
            if name not in vl.aovs:
                aov = vl.aovs.add()
                aov.name = name
                aov.type = "VALUE"
        vl.cycles.denoising_store_passes = denoise
    tree = scene.compositing_node_group
    if tree is not None and tree.name != COMPOSITOR and not tree.name.startswith(COMPOSITOR + "."):
        raise RuntimeError(f"scene {scene.name!r} already has a compositor ({tree.name!r}): wire it "
                           f"by hand as Image - Combined_{KEY_GROUP} * {AOV} from the Render Layers "
                           "node, or remove it and call occlude_key_light again")
    if tree is None:
        tree = bpy.data.node_groups.new(COMPOSITOR, "CompositorNodeTree")
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        scene.compositing_node_group = tree
    tree.nodes.clear()
    rl = tree.nodes.new("CompositorNodeRLayers")
    rl.scene = scene

    def mix(op):
        node = tree.nodes.new("ShaderNodeMix")
        node.data_type = "RGBA"
        node.blend_type = op
        node.inputs["Factor"].default_value = 1.0
        return node

    mul, sub = mix("MULTIPLY"), mix("SUBTRACT")
    tree.links.new(rl.outputs[f"Combined_{KEY_GROUP}"], mul.inputs["A"])
    tree.links.new(rl.outputs[AOV], mul.inputs["B"])
    tree.links.new(rl.outputs["Image"], sub.inputs["A"])
    tree.links.new(mul.outputs["Result"], sub.inputs["B"])
    result = sub.outputs["Result"]
    if ambient:
        rest, mul2, sub2 = mix("SUBTRACT"), mix("MULTIPLY"), mix("SUBTRACT")
        tree.links.new(rl.outputs["Image"], rest.inputs["A"])
        tree.links.new(rl.outputs[f"Combined_{KEY_GROUP}"], rest.inputs["B"])
        tree.links.new(rest.outputs["Result"], mul2.inputs["A"])
        tree.links.new(rl.outputs[AMBIENT_AOV], mul2.inputs["B"])
        tree.links.new(result, sub2.inputs["A"])
        tree.links.new(mul2.outputs["Result"], sub2.inputs["B"])
        result = sub2.outputs["Result"]
    if denoise:
        dn = tree.nodes.new("CompositorNodeDenoise")
        tree.links.new(result, dn.inputs["Image"])
        tree.links.new(rl.outputs["Denoising Normal"], dn.inputs["Normal"])
        tree.links.new(rl.outputs["Denoising Albedo"], dn.inputs["Albedo"])
        result = dn.outputs["Image"]
    out = tree.nodes.new("NodeGroupOutput")
    tree.links.new(result, out.inputs[0])
    for i, n in enumerate(tree.nodes):
        n.location = (220 * i, 0)
    return tree


def build_material(path, light, mode="nodes", output="lit", albedo=(0.8, 0.7, 0.6, 1.0),
                   repeat=1.0, interpolation="Linear", name=None, scene=None, maps="auto"):
    """A material evaluating the PTM at `path` (any of its parts, or `w.ptm.exr`) for the key
    light object named `light` (or the object itself), tiled `repeat` times across the UV square
    (a number, or (across, down) for a UV map that is not square in space, like a UV sphere's).
    See the module docstring; with
    ``output="lit"`` it also calls ``occlude_key_light(light, scene)``.

    `maps`: the companion maps of the same bake (``ptm bake --maps --maps-png``): "auto" (the
    default) takes those that ``companion_maps(path)`` finds, a dict {"normal": png, "ao": png}
    names them, None uses none. The normal map (tangent space, +Y up: Blender's Normal Map node
    as it is) feeds the BSDF's normal (K keeps the mesh's own frame: the PTM was baked against
    the tile's plane); AO darkens everything but the key light (``occlude_key_light(ambient=True)``),
    so only with ``output="lit"``."""
    if output not in ("lit", "multiply", "k"):
        raise ValueError(f"output {output!r}: lit, multiply or k")
    stem, basis, link, uv = ptm_info(path)
    if maps == "auto":
        maps = companion_maps(path) if output != "k" else {}
    maps = dict(maps or {})
    unknown = set(maps) - {"normal", "ao"}
    if unknown:
        raise ValueError(f"maps: unknown map(s) {sorted(unknown)}; normal and ao are used")
    if "ao" in maps and output != "lit":
        raise ValueError(f"maps: an AO map darkens the light other than the key, which needs "
                         f"output=\"lit\" (got {output!r}); leave AO out for {output!r}")
    light_obj = _light_object(light)
    mat = bpy.data.materials.new(name or f"PTM {os.path.basename(stem)} ({mode})")
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    texco = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")
    rx, ry = (repeat, repeat) if isinstance(repeat, (int, float)) else repeat
    mapping.inputs["Scale"].default_value = (rx, ry, 1.0)
    tree.links.new(texco.outputs["UV"], mapping.inputs["Vector"])
    if mode == "osl":
        bpy.context.scene.render.engine = "CYCLES"
        bpy.context.scene.cycles.device = "CPU"
        bpy.context.scene.cycles.shading_system = True
        learned = basis.startswith("learned")
        shader = OSL_LEARNED if learned else OSL_SHADER
        node = tree.nodes.new("ShaderNodeScript")
        node.mode = "EXTERNAL"
        node.filepath = os.path.abspath(shader)
        node.update()
        if "stem" not in node.inputs:
            raise RuntimeError(f"{shader}: Blender did not compile the OSL shader")
        node.inputs["stem"].default_value = os.path.abspath(stem)
        if learned:
            params = ptm_params.learned_params(stem + ".c0.exr")
            node.inputs["terms"].default_value = params["terms"]
            node.inputs["grid"].default_value = params["grid"]
        else:
            node.inputs["basis"].default_value = 11 if basis == "ptm11" else 6
            node.inputs["link"].default_value = 1 if link == "logistic" else 0
            node.inputs["uvmap"].default_value = 1 if uv == "hemispherical" else 0
        # OSL's texture() names its modes "closest", "linear", "cubic", "smartcubic" (the OSL
        # spec; the learned shader reads its basis with "linear"); OIIO's "bilinear" is not one.
        node.inputs["interp"].default_value = {"Closest": "closest", "Linear": "linear",
                                                "Cubic": "cubic"}.get(interpolation, "smartcubic")
        tree.links.new(mapping.outputs["Vector"], node.inputs["UV"])
        # Cycles' dPdu follows the triangle, not the UV map: pass the UV tangent.
        tangent = tree.nodes.new("ShaderNodeTangent")
        tangent.direction_type = "UV_MAP"
        tree.links.new(tangent.outputs["Tangent"], node.inputs["Tangent"])
        light_in = node.inputs["light_dir"]
    elif mode == "nodes":
        node = tree.nodes.new("ShaderNodeGroup")
        node.node_tree = occlusion_group(stem, basis, link, uv, interpolation)
        tree.links.new(mapping.outputs["Vector"], node.inputs["Vector"])
        light_in = node.inputs["Light"]
    else:
        raise ValueError(f"mode {mode!r}: osl or nodes")
    _connect_light(tree, light_in, light_obj)
    if output == "k":
        emit = tree.nodes.new("ShaderNodeEmission")
        emit.inputs["Strength"].default_value = 1.0
        tree.links.new(node.outputs["K"], emit.inputs["Color"])
        tree.links.new(emit.outputs[0], out.inputs["Surface"])

    def map_image(file):
        img = bpy.data.images.load(os.path.abspath(file), check_existing=True)
        img.colorspace_settings.name = "Non-Color"
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image, tex.interpolation, tex.extension = img, interpolation, "REPEAT"
        tree.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        return tex

    def apply_normal_map(bsdf):
        if "normal" in maps:
            nmap = tree.nodes.new("ShaderNodeNormalMap")
            nmap.space = "TANGENT"
            tree.links.new(map_image(maps["normal"]).outputs["Color"], nmap.inputs["Color"])
            tree.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])

    if output == "multiply":
        bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
        tint = tree.nodes.new("ShaderNodeMix")
        tint.data_type = "RGBA"
        tint.blend_type = "MULTIPLY"
        tint.inputs["Factor"].default_value = 1.0
        tint.inputs["A"].default_value = albedo
        tree.links.new(node.outputs["Visibility"], tint.inputs["B"])
        tree.links.new(tint.outputs["Result"], bsdf.inputs["Base Color"])
        tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
        apply_normal_map(bsdf)
    elif output == "lit":
        bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
        bsdf.inputs["Base Color"].default_value = albedo
        tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
        apply_normal_map(bsdf)
        aov = tree.nodes.new("ShaderNodeOutputAOV")
        aov.aov_name = AOV
        tree.links.new(node.outputs["K"], aov.inputs["Value"])
        if "ao" in maps:
            occ = tree.nodes.new("ShaderNodeMath")
            occ.operation = "SUBTRACT"
            occ.inputs[0].default_value = 1.0
            tree.links.new(map_image(maps["ao"]).outputs["Color"], occ.inputs[1])
            amb = tree.nodes.new("ShaderNodeOutputAOV")
            amb.aov_name = AMBIENT_AOV
            tree.links.new(occ.outputs[0], amb.inputs["Value"])
        occlude_key_light(light_obj, scene, ambient="ao" in maps)
    return mat


def apply_material(obj, path, light, repeat=1.0, uv_map=None, albedo=(0.8, 0.7, 0.6, 1.0),
                   mode="nodes", output="lit", maps="auto", scene=None):
    """The whole lookdev material on a user's mesh in one call: ``build_material`` for the PTM at
    `path` with its companion maps (``NAME.normal.png``, ``NAME.ao.png`` beside it, from ``ptm
    bake --maps --maps-png``; ``maps`` as in ``build_material``), tiled `repeat` times per UV
    unit (a number, or (across, down)), the key light `light` occluded by K (``output="lit"``:
    its light group and the compositor), assigned to every material slot of `obj` (an object or
    its name; the material replaces what the slots held, and a mesh without slots gets one).

    `uv_map` names the UV map the PTM, the normal map and the tangents follow (default: the
    mesh's active render UV map); it becomes the active render UV map, which is what the
    material's Texture Coordinate, Normal Map and Tangent nodes read. Returns the material.

    Refused with ``ValueError`` naming the object: not a mesh, no UV map (the PTM tiles over the
    UVs: unwrap it first, UV ▸ Unwrap), or a `uv_map` it does not have."""
    if isinstance(obj, str):
        if obj not in bpy.data.objects:
            raise ValueError(f"apply_material: no object named {obj!r}")
        obj = bpy.data.objects[obj]
    if obj.type != "MESH":
        raise ValueError(f"apply_material: {obj.name!r} is a {obj.type.lower()}, not a mesh")
    uvs = obj.data.uv_layers
    if len(uvs) == 0:
        raise ValueError(f"apply_material: mesh {obj.name!r} has no UV map, and the PTM tiles over "
                         "the UVs: unwrap it (Edit Mode, UV ▸ Unwrap) or import it with its UVs")
    if uv_map is not None:
        if uv_map not in uvs:
            raise ValueError(f"apply_material: mesh {obj.name!r} has no UV map {uv_map!r} "
                             f"(it has {', '.join(repr(u.name) for u in uvs)})")
        uvs[uv_map].active_render = True
        uvs.active = uvs[uv_map]
    mat = build_material(path, light, mode=mode, output=output, albedo=albedo, repeat=repeat,
                         name=f"PTM {os.path.basename(stem_of(path))} on {obj.name}", scene=scene,
                         maps=maps)
    slots = obj.data.materials
    if len(slots) == 0:
        slots.append(mat)
    for i in range(len(slots)):
        slots[i] = mat
    return mat
