"""Headless Blender (PyPI `bpy`) test of integrations/blender/ptm_blender.py: renders a plane in
Cycles CPU emitting K (OSL script node and Blender-node group) under several light directions
and compares every pixel centre with the Rust `Ptm::eval_dir` (fit/examples/ptm_eval.rs).
The same for the OSL that MaterialX's generator writes for ND_ptm_occlusion_float
(integrations/materialx/mtlx_osl.py makes MTLX_OSL, and its `_learned` twin for
ND_ptm_occlusion_learned_float), compiled by Cycles' OSL compiler: a compile error fails the
test with the compiler's message. Learned bases (learned11, learned6) go through
ptm_occlusion_learned.osl, the node group and the learned MaterialX OSL alike.
The README's OSL shader group is built as written and lit: its shadowing equals 1 − Ptm::eval.
The README's Blender examples run as written (the Python block in a fresh default scene, the
ptm_scene.py command line); output="lit" occludes the key light only (composite = Image − key
pass × K, never darker than the world alone), where output="multiply" darkens the world light too.
``apply_material`` sets the whole material (PTM, normal map, AO) on a user's imported OBJ in one
call; K and AO only darken its render.
Then renders the lit example (plane tiled 4×, micro-shadows from one key sun) to a PNG.

    python test_blender.py PTM_BIN PTM_EVAL MTLX_OSL WORKDIR [LIT_PNG]
"""
import json
import math
import os
import subprocess
import sys
import time

import bpy
import mathutils

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import ptm_blender  # noqa: E402

PTM, EVAL, MTLX_OSL, WORK = sys.argv[1:5]
LIT_PNG = sys.argv[5] if len(sys.argv) > 5 else None
RES = 16
TOL = 1e-3
DIRS = [(0.0, 0.0, 1.0), (0.6, 0.2, 0.5), (-0.5, 0.7, 0.4), (0.3, -0.8, 0.35), (-0.9, -0.3, 0.25),
        (0.2, 0.97, 0.06)]  # the last one grazing (3.4° elevation)
CASES = [
    ("ptm6", "identity", "projected"),
    ("ptm6", "logistic", "hemispherical"),
    ("ptm11", "identity", "hemispherical"),
    ("ptm11", "logistic", "projected"),
    # Learned bases (always logistic, hemispherical): three basis parts beside the coefficient
    # parts' last A (learned11), and a padded last part (learned6: c1 = b4 b5 unused coverage).
    ("learned11", "logistic", "hemispherical"),
    ("learned6", "logistic", "hemispherical"),
]


def scene_setup():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 1
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = False
    sc.cycles.pixel_filter_type = "BOX"
    sc.cycles.filter_width = 1.0
    sc.render.resolution_x = sc.render.resolution_y = RES
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    sc.world = world
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    plane = bpy.context.active_object
    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = 2.0
    cam = bpy.data.objects.new("cam", cam_data)
    cam.location = (0, 0, 5)
    sc.collection.objects.link(cam)
    sc.camera = cam
    sun_data = bpy.data.lights.new("Key", "SUN")
    sun = bpy.data.objects.new("Key", sun_data)
    sc.collection.objects.link(sun)
    return sc, plane, sun


def aim(sun, d):
    v = mathutils.Vector(d).normalized()
    sun.rotation_euler = v.to_track_quat("Z", "Y").to_euler()
    bpy.context.view_layer.update()


def render_k(sc, path):
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    px = list(img.pixels)
    w, h = img.size
    bpy.data.images.remove(img)
    # Blender's pixels run bottom to top; our rows top to bottom.
    return [[px[((h - 1 - r) * w + c) * 4] for c in range(w)] for r in range(h)]


def compile_osl(path):
    """Compiles `path` with Cycles' OSL compiler (liboslcomp in bpy) to an .oso beside it in
    WORK; returns the .oso path, or exits naming the compiler's messages."""
    import _cycles

    oso = os.path.join(WORK, os.path.basename(path)[:-4] + ".oso")
    log = os.path.join(WORK, "oslc.log")
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(fd, 1)
    os.dup2(fd, 2)  # the compiler prints its errors to the process's stdout / stderr
    try:
        ok = _cycles.osl_compile(path, oso)
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(fd)
    msg = open(log).read().strip()
    if not ok:
        print(f"blender: FAILED: Cycles' OSL compiler rejects {path}:\n" +
              "\n".join("blender:   " + line for line in msg.splitlines()))
        sys.exit(1)
    return oso


def mtlx_material(oso, stem, basis, link, uv, light_obj):
    """Emission of K from the MaterialX-generated shader (mtlx_osl.py's parameters) in a Script node."""
    mat = bpy.data.materials.new(f"MaterialX OSL {os.path.basename(stem)}")
    mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new("ShaderNodeScript")
    node.mode = "EXTERNAL"
    node.filepath = oso
    node.update()
    if "uv" not in node.inputs or "out" not in node.outputs:
        print(f"blender: FAILED: the Script node did not load {oso} (inputs {list(node.inputs.keys())})")
        sys.exit(1)
    if basis.startswith("learned"):
        params = ptm_blender.ptm_params.learned_params(stem + ".c0.exr")
        for k, (part, table) in enumerate(zip(params["parts"], params["basis_parts"])):
            node.inputs[f"part{k}"].default_value = os.path.abspath(part)
            node.inputs[f"basis{k}"].default_value = os.path.abspath(table)
        node.inputs["grid"].default_value = params["grid"]
    else:
        nparts = 3 if basis == "ptm11" else 2
        for k in range(nparts):
            node.inputs[f"part{k}"].default_value = os.path.abspath(f"{stem}.c{k}.exr")
        node.inputs["basis"].default_value = 11 if basis == "ptm11" else 6
        node.inputs["link"].default_value = 1 if link == "logistic" else 0
        node.inputs["uvmap"].default_value = 1 if uv == "hemispherical" else 0
    node.inputs["filtertype"].default_value = "closest"
    texco = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(texco.outputs["UV"], node.inputs["uv"])
    tangent = tree.nodes.new("ShaderNodeTangent")  # MaterialX's Tworld is dPdu: the triangle's
    tangent.direction_type = "UV_MAP"
    tree.links.new(tangent.outputs["Tangent"], node.inputs["tangent"])
    node.inputs["light"].default_value = ptm_blender.light_direction(light_obj)
    ptm_blender._drive_light_dir(node.inputs["light"], light_obj)
    emit = tree.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    tree.links.new(node.outputs["out"], emit.inputs["Color"])
    tree.links.new(emit.outputs[0], out.inputs["Surface"])
    return mat


def readme_osl_group():
    """The README's OSL shader group (integrations/osl/test_readme_example.py reads it) built as
    Script nodes with its parameters as written, plus what Cycles needs beside them (the UV and
    the UV tangent, as the README says; closest lookups so pixel centres are texel values), lit
    by a sun along its light_dir. The render divided by the same render with `visibility` left
    at 1 is the visibility 1 − K: compared with Ptm::eval at every pixel centre."""
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "osl"))
    from test_readme_example import readme_group

    layers, connections = readme_group()
    key = layers[0][2]
    stem = os.path.join(WORK, key["stem"][1][0])
    basis = f"ptm{key['basis'][1][0]}"
    link = ["identity", "logistic"][key["link"][1][0]]
    uv = ["projected", "hemispherical"][key["uvmap"][1][0]]
    light = key["light_dir"][1]
    subprocess.run([PTM, "bake", "--res", str(RES), "--spp", "4", "--dirs", "64", "--fit", basis, "--link", link,
                    "--uv", uv, "--layout", "rgba", "-o", stem + ".exr"], check=True, capture_output=True)
    ref = json.loads(subprocess.run([EVAL, stem + ".c0.exr", ",".join(map(str, light))],
                                    check=True, capture_output=True, text=True).stdout)[0]
    renders = []
    cwd = os.getcwd()
    os.chdir(WORK)  # the README's stem is relative
    try:
        for wired in (True, False):
            sc, plane, sun = scene_setup()
            sun.data.angle = 0.0
            aim(sun, light)
            sc.cycles.shading_system = True
            mat = bpy.data.materials.new("README OSL group")
            mat.use_nodes = True
            tree = mat.node_tree
            tree.nodes.clear()
            nodes = {}
            for shader, layer, params in layers:
                node = tree.nodes.new("ShaderNodeScript")
                node.mode = "EXTERNAL"
                node.filepath = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "osl", shader + ".osl"))
                node.update()
                for pname, (ty, values) in params.items():
                    node.inputs[pname].default_value = values[0] if len(values) == 1 else values
                nodes[layer] = node
            if wired:
                for sl, sp, dl, dp in connections:
                    tree.links.new(nodes[sl].outputs[sp], nodes[dl].inputs[dp])
            first = nodes[layers[0][1]]
            texco = tree.nodes.new("ShaderNodeTexCoord")
            tree.links.new(texco.outputs["UV"], first.inputs["UV"])
            tangent = tree.nodes.new("ShaderNodeTangent")
            tangent.direction_type = "UV_MAP"
            tree.links.new(tangent.outputs["Tangent"], first.inputs["Tangent"])
            first.inputs["interp"].default_value = "closest"
            out = tree.nodes.new("ShaderNodeOutputMaterial")
            tree.links.new(nodes[layers[-1][1]].outputs[0], out.inputs["Surface"])
            plane.data.materials.append(mat)
            renders.append(render_k(sc, os.path.join(WORK, f"readme-osl-{wired}.exr")))
    finally:
        os.chdir(cwd)
    lit, bare = renders
    assert min(min(r) for r in bare) > 1e-3, "the unshadowed README render is black: no light reached it"
    err = max(abs(lit[r][c] / bare[r][c] - (1 - ref[r][c])) for r in range(RES) for c in range(RES))
    spread = max(max(r) for r in ref) - min(min(r) for r in ref)
    assert spread > 0.05, f"K is flat under the README's light {light}; the test would prove nothing"
    print(f"blender: README OSL shader group ({' + '.join(l[0] for l in layers)}), lit: "
          f"render / unshadowed render = 1 - Ptm::eval to {err:.2e}", flush=True)
    return err


def load_rgb(path):
    """The R, G, B values (0..1) of an image file, all pixels in one list."""
    img = bpy.data.images.load(os.path.abspath(path))
    px = list(img.pixels)
    bpy.data.images.remove(img)
    return [v for i, v in enumerate(px) if i % 4 != 3]


def render_socket(sc, socket, path):
    """Renders with the compositor's output wired to the Render Layers output `socket` (a pass),
    then rewires it as it was."""
    tree = sc.compositing_node_group
    rl = next(n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers")
    out = next(n for n in tree.nodes if n.bl_idname == "NodeGroupOutput")
    old = out.inputs[0].links[0].from_socket
    tree.links.new(rl.outputs[socket], out.inputs[0])
    try:
        return render_k(sc, path)
    finally:
        tree.links.new(old, out.inputs[0])


def key_light_only():
    """output="lit" occludes the key light only (issue #25, item 3). A plane under a key sun and
    a 0.15 grey world: the AOV carries K (= Ptm::eval at the pixel centres), the composite is
    Image − key pass × K, and no pixel renders darker than the world alone lights it. The old
    base-colour multiply (output="multiply") is rendered too: it must darken some texels below
    the world-only level, or this test could not tell the two apart."""
    name = os.path.join(WORK, "key.ptm.exr")
    subprocess.run([PTM, "bake", "--res", str(RES), "--spp", "4", "--dirs", "64", "--fit", "ptm11",
                    "--link", "logistic", "--uv", "hemispherical", "--layout", "rgba", "-o", name],
                   check=True, capture_output=True)
    d = (0.55, 0.55, 0.35)
    ref = json.loads(subprocess.run([EVAL, ptm_blender.stem_of(name) + ".c0.exr", ",".join(map(str, d))],
                                    check=True, capture_output=True, text=True).stdout)[0]
    got = {}
    for output in ("lit", "multiply"):
        sc, plane, sun = scene_setup()
        bg = sc.world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bg.inputs["Strength"].default_value = 0.15
        sun.data.energy = 3.0
        sun.data.angle = 0.0
        aim(sun, d)
        sc.cycles.samples = 16
        plane.data.materials.append(ptm_blender.build_material(name, light="Key", output=output,
                                                               interpolation="Closest"))
        got[output] = render_k(sc, os.path.join(WORK, f"key-{output}.exr"))
        if output == "lit":
            for socket in ("Image", f"Combined_{ptm_blender.KEY_GROUP}", ptm_blender.AOV):
                got[socket] = render_socket(sc, socket, os.path.join(WORK, f"key-{socket}.exr"))
    # A point light far along d (the position path of _connect_light): the direction from each
    # shading point to it is d to 1e-5 rad, so K must match the sun's reference (the error
    # scales as 1/distance, as geometry says: 5e-3 at 1e3, 5e-5 at 1e5).
    sc, plane, sun = scene_setup()
    point = bpy.data.objects.new("Point", bpy.data.lights.new("Point", "POINT"))
    sc.collection.objects.link(point)
    point.location = mathutils.Vector(d).normalized() * 1e5
    bpy.context.view_layer.update()
    plane.data.materials.append(ptm_blender.build_material(name, light="Point", output="k",
                                                           interpolation="Closest"))
    k_point = render_k(sc, os.path.join(WORK, "key-point.exr"))
    px = [(r, c) for r in range(RES) for c in range(RES)]
    err_point = max(abs(k_point[r][c] - ref[r][c]) for r, c in px)
    image, key, aov = got["Image"], got[f"Combined_{ptm_blender.KEY_GROUP}"], got[ptm_blender.AOV]
    rest = {(r, c): image[r][c] - key[r][c] for r, c in px}
    err_k = max(abs(aov[r][c] - ref[r][c]) for r, c in px)
    err_comp = max(abs(got["lit"][r][c] - (image[r][c] - key[r][c] * ref[r][c])) for r, c in px)
    below_lit = min(got["lit"][r][c] - rest[r, c] for r, c in px)
    dark_mul = sum(got["multiply"][r][c] < rest[r, c] - 0.02 for r, c in px)
    shadowed = sum(ref[r][c] > 0.5 for r, c in px)
    print(f"blender: point light far along the sun's direction: K vs Ptm::eval {err_point:.2e}")
    print(f"blender: key-light occlusion: AOV K vs Ptm::eval {err_k:.2e}, composite vs Image - key*K "
          f"{err_comp:.2e}, lowest composite - world-only {below_lit:+.2e} over {len(px)} pixels "
          f"({shadowed} with K > 0.5); output=\"multiply\" renders {dark_mul} pixels darker than the "
          "world alone", flush=True)
    problems = []
    if shadowed == 0:
        problems.append("no pixel has K > 0.5: the test would prove nothing")
    if not err_k <= TOL:
        problems.append(f"AOV K off by {err_k:.2e}")
    if not err_point <= TOL:
        problems.append(f"K under a point light off by {err_point:.2e}")
    if not err_comp <= TOL * max(max(row) for row in image):
        problems.append(f"composite off by {err_comp:.2e}")
    if not below_lit >= -1e-5:
        problems.append(f"composite darker than the world alone by {-below_lit:.2e}")
    if dark_mul == 0:
        problems.append("output=multiply darkened nothing below the world level: the test cannot tell")
    return err_k, problems


def maps_lit():
    """build_material with the bake's companion maps (`ptm bake --maps --maps-png`): the normal
    map turns the key light's Lambert term into n_map · l (a plane's tangent frame is the world
    frame, so the map's decoded normal is the world normal), and the AO map multiplies all light
    but the key: composite = Image − key × K − (Image − key) × (1 − AO), AO read from the PNG at
    the pixel centres. Returns (worst error, problems)."""
    name = os.path.join(WORK, "maps.ptm.exr")
    subprocess.run([PTM, "bake", "--res", str(RES), "--spp", "4", "--dirs", "64", "--fit", "ptm11",
                    "--link", "logistic", "--layout", "rgba", "--maps", "--maps-png", "-o", name],
                   check=True, capture_output=True)
    found = ptm_blender.companion_maps(name)
    if set(found) != {"normal", "ao"}:
        return 1.0, [f"ptm bake --maps --maps-png wrote {sorted(found)} of normal, ao beside {name}"]
    d = mathutils.Vector((0.3, 0.45, 0.84)).normalized()
    ref = json.loads(subprocess.run([EVAL, ptm_blender.stem_of(name) + ".c0.exr", ",".join(map(str, d))],
                                    check=True, capture_output=True, text=True).stdout)[0]
    got = {}
    for maps in ("auto", None):
        sc, plane, sun = scene_setup()
        bg = sc.world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bg.inputs["Strength"].default_value = 0.15
        sun.data.energy = 3.0
        sun.data.angle = 0.0
        aim(sun, d)
        sc.cycles.samples = 16
        mat = ptm_blender.build_material(name, light="Key", output="lit", interpolation="Closest", maps=maps)
        bsdf = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
        bsdf.inputs["Specular IOR Level"].default_value = 0.0  # Lambert only: the key is n · l
        plane.data.materials.append(mat)
        sockets = ["Combined", f"Combined_{ptm_blender.KEY_GROUP}"]
        if maps:
            got["composite"] = render_k(sc, os.path.join(WORK, "maps-composite.exr"))
            sockets += [ptm_blender.AMBIENT_AOV]
        for socket in sockets:
            got[(maps, socket)] = render_socket(sc, socket if socket != "Combined" else "Image",
                                                os.path.join(WORK, f"maps-{maps}-{socket}.exr"))
    img = bpy.data.images.load(found["ao"])
    img.colorspace_settings.name = "Non-Color"
    px, (w, h) = list(img.pixels), img.size
    ao = [[px[((h - 1 - r) * w + c) * 4] for c in range(w)] for r in range(h)]
    img = bpy.data.images.load(found["normal"])
    img.colorspace_settings.name = "Non-Color"
    npx = list(img.pixels)
    if (w, h) != (RES, RES) or tuple(img.size) != (RES, RES):
        return 1.0, [f"maps are {w}×{h} and {tuple(img.size)}, the PTM {RES}×{RES}"]
    cells = [(r, c) for r in range(RES) for c in range(RES)]
    image, key = got[("auto", "Combined")], got[("auto", f"Combined_{ptm_blender.KEY_GROUP}")]
    amb = got[("auto", ptm_blender.AMBIENT_AOV)]
    err_amb = max(abs(amb[r][c] - (1 - ao[r][c])) for r, c in cells)
    expect = {(r, c): image[r][c] - key[r][c] * ref[r][c] - (image[r][c] - key[r][c]) * (1 - ao[r][c])
              for r, c in cells}
    err_comp = max(abs(got["composite"][r][c] - expect[r, c]) for r, c in cells)
    # The key's Lambert term with the map over without it: (n_map · l) / (n_geo · l), n_geo = +Z.
    # Cycles damps the diffuse of a bent shading normal (its bump shadowing term, Chiang et al.
    # 2019): 1 % at 40° of tilt, 6 % at 66°; so the mean is held to 1 %, and the map read with
    # its green axis flipped (the DirectX convention) must be far off, or the test cannot tell.
    key_plain = got[(None, f"Combined_{ptm_blender.KEY_GROUP}")]
    errs = {1: [], -1: []}
    for r, c in cells:
        i = ((RES - 1 - r) * RES + c) * 4
        for flip in (1, -1):
            n = mathutils.Vector([2 * npx[i + k] - 1 for k in range(3)]).normalized()
            n.y *= flip
            want = max(n.dot(d), 0.0) / d.z
            errs[flip].append(abs(key[r][c] / key_plain[r][c] - want))
    err_n, err_flipped = (sum(e) / len(e) for e in (errs[1], errs[-1]))
    aos = [ao[r][c] for r, c in cells]
    print(f"blender: companion maps: ambient AOV vs 1 - AO(png) {err_amb:.2e}, composite vs "
          f"Image - key*K - rest*(1 - AO) {err_comp:.2e} (AO {min(aos):.2f}..{max(aos):.2f}); "
          f"key with / without the normal map vs n_map.l / n_geo.l: mean {err_n:.2e}, max "
          f"{max(errs[1]):.2e} (green flipped: mean {err_flipped:.2e})", flush=True)
    problems = []
    if not err_amb <= TOL:
        problems.append(f"ambient AOV off by {err_amb:.2e}")
    if not err_comp <= TOL * max(max(row) for row in image):
        problems.append(f"composite with AO off by {err_comp:.2e}")
    if not err_n <= 1e-2:
        problems.append(f"normal map: key light ratio off by {err_n:.2e} on average")
    if not err_flipped > 0.1:
        problems.append(f"normal map: a flipped green axis is off by only {err_flipped:.2e}: the test cannot tell")
    if max(aos) - min(aos) < 0.1:
        problems.append("AO is nearly flat: the test would prove nothing")
    return max(err_amb, err_comp), problems


def user_mesh():
    """``apply_material`` on a mesh of the user's (an OBJ written here, imported with Blender's
    OBJ importer: a wavy 2 × 1 sheet with its own UVs and two material slots, not one of our
    built-ins) in one call: the material in every slot, the companion maps picked up (normal
    map, AO), K in the AOV on the mesh, and the composite (key × K and the rest × (1 − AO) taken
    off) nowhere lighter and on average darker than the render before it. A mesh without UVs is
    refused by name. Returns problems."""
    name = os.path.join(WORK, "maps.ptm.exr")  # baked with its maps by maps_lit()
    obj_path = os.path.join(WORK, "user_garment.obj")
    nu, nv = 24, 12
    with open(obj_path[:-4] + ".mtl", "w") as f:
        f.write("newmtl front\nKd 0.8 0.2 0.2\nnewmtl back\nKd 0.2 0.2 0.8\n")
    with open(obj_path, "w") as f:
        f.write("# a wavy sheet with UVs, two materials\nmtllib user_garment.mtl\n")
        for j in range(nv + 1):
            for i in range(nu + 1):
                x, y = -1.0 + 2.0 * i / nu, -0.5 + j / nv
                f.write(f"v {x:.6f} {y:.6f} {0.12 * math.sin(3.0 * x) * math.cos(2.0 * y):.6f}\n")
        for j in range(nv + 1):
            for i in range(nu + 1):
                f.write(f"vt {2.0 * i / nu:.6f} {j / nv:.6f}\n")
        for j in range(nv):
            f.write(f"usemtl {'front' if j < nv // 2 else 'back'}\n")
            for i in range(nu):
                a = j * (nu + 1) + i + 1
                q = (a, a + 1, a + nu + 2, a + nu + 1)
                f.write("f " + " ".join(f"{k}/{k}" for k in q) + "\n")
    sc, plane, sun = scene_setup()
    bpy.data.objects.remove(plane)
    bpy.ops.wm.obj_import(filepath=obj_path, forward_axis="Y", up_axis="Z")
    obj = bpy.context.selected_objects[0]
    sc.camera.location = (0.0, -2.2, 2.0)
    sc.camera.data.type = "PERSP"
    sc.camera.rotation_euler = (mathutils.Vector((0, 0, 0)) - sc.camera.location).to_track_quat("-Z", "Y").to_euler()
    bg = sc.world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bg.inputs["Strength"].default_value = 0.15
    sun.data.energy = 3.0
    aim(sun, (0.5, 0.3, 0.6))
    sc.cycles.samples = 4
    sc.render.resolution_x, sc.render.resolution_y = 48, 32
    problems = []
    slots_before = len(obj.data.materials)
    mat = ptm_blender.apply_material(obj, name, light="Key", repeat=4.0)
    kinds = {n.bl_idname for n in mat.node_tree.nodes}
    nmap = [n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeNormalMap"]
    images = {os.path.basename(n.image.filepath) for n in mat.node_tree.nodes
              if n.bl_idname == "ShaderNodeTexImage" and n.image}
    if slots_before != 2 or list(obj.data.materials) != [mat, mat]:
        problems.append(f"slots: {slots_before} before, {[m.name for m in obj.data.materials]} after")
    if not nmap or not {"maps.normal.png", "maps.ao.png"} <= images or "ShaderNodeGroup" not in kinds:
        problems.append(f"material lacks the PTM group, normal map or AO: {sorted(kinds)}, {sorted(images)}")
    # The composite against the same render before the compositor: K and AO only darken it (the
    # normal map may lighten a texel facing the key: it is in both); K is on the mesh.
    composite = render_k(sc, os.path.join(WORK, "user-composite.exr"))
    raw = render_socket(sc, "Image", os.path.join(WORK, "user-image.exr"))
    k = render_socket(sc, ptm_blender.AOV, os.path.join(WORK, "user-k.exr"))
    cells = [(r, c) for r in range(len(raw)) for c in range(len(raw[0])) if raw[r][c] > 0.02]
    diff = [raw[r][c] - composite[r][c] for r, c in cells]
    mean = sum(diff) / max(len(diff), 1)
    kmax = max((k[r][c] for r, c in cells), default=0.0)
    print(f"blender: apply_material on a user's OBJ ({len(obj.data.polygons)} faces, 2 slots): "
          f"image - composite over {len(cells)} pixels: mean {mean:.4f}, lowest {min(diff):+.4f}; "
          f"K up to {kmax:.2f}", flush=True)
    if len(cells) < 200:
        problems.append(f"the mesh covers only {len(cells)} pixels")
    if min(diff) < -2e-3:
        problems.append(f"the composite is lighter than the render by {-min(diff):.4f} somewhere")
    if not mean > 0.005 or not kmax > 0.05:
        problems.append(f"K and AO darken the user's mesh by only {mean:.4f} on average (K up to "
                        f"{kmax:.2f}): are they applied?")
    me = bpy.data.meshes.new("no-uv")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0)], [], [(0, 1, 2)])
    bare = bpy.data.objects.new("bare sheet", me)
    sc.collection.objects.link(bare)
    try:
        ptm_blender.apply_material(bare, name, light="Key")
        problems.append("a mesh without UVs was accepted")
    except ValueError as e:
        if "bare sheet" not in str(e) or "UV" not in str(e):
            problems.append(f"a mesh without UVs refused in other words: {e}")
    return problems


def readme_blender(fresh_scene_block, command_block):
    """The Blender examples of docs/pipeline.md as written: the Python-console block in a fresh
    default scene (a cube, a point light named "Light", a camera), then rendered; the one-line
    scene script through bpy (`blender --background --python` → this Python)."""
    name = os.path.join(WORK, "w.ptm.exr")
    subprocess.run([PTM, "convert", os.path.join(WORK, "ptm11-logistic.ptm.exr"), "-o", name,
                    "--layout", "rgba"], check=True, capture_output=True)
    bpy.ops.wm.read_factory_settings(use_empty=False)
    cwd = os.getcwd()
    os.chdir(WORK)
    try:
        exec(compile(fresh_scene_block, "docs/pipeline.md (Blender example)", "exec"), {})
        sc = bpy.context.scene
        plane = bpy.context.active_object
        assert plane.data.materials and plane.data.materials[0].node_tree, "README example made no material"
        sc.render.resolution_x = sc.render.resolution_y = RES
        sc.cycles.samples = 1
        sc.render.filepath = os.path.join(WORK, "readme.png")
        bpy.ops.render.render(write_still=True)
        assert os.path.exists(sc.render.filepath), "README example rendered nothing"
        print("blender: README Python example builds its material and renders in a fresh default scene")
        repo = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
        if not os.path.exists("integrations"):
            os.symlink(os.path.abspath(os.path.join(repo, "integrations")), "integrations")
        lines = [ln for ln in command_block.splitlines() if ln.startswith("blender ")]
        assert len(lines) == 1, f"docs/pipeline.md: expected one `blender …` line, found {lines}"
        argv = lines[0].split()
        assert argv[:4] == ["blender", "--background", "--python", "integrations/blender/ptm_scene.py"], argv
        args = argv[5:] + ["--res", "48", "--samples", "2"]
        t = time.time()
        run = subprocess.run([sys.executable, argv[3]] + args, capture_output=True, text=True)
        assert run.returncode == 0, f"{lines[0]}: exit {run.returncode}:\n{run.stderr[-2000:]}"
        out = args[1]
        assert os.path.getsize(out) > 0, f"{lines[0]}: wrote no {out}"
        print(f"blender: README scene command runs as written ({time.time() - t:.1f} s): "
              + [ln for ln in run.stdout.splitlines() if ln.startswith("ptm_scene:")][-1])
        # The drape, with and without the map: the occlusion only ever darkens (the key light's
        # share), and it darkens the cloth visibly. Without the denoiser, whose output is not
        # monotonic in its input (with it, a few pixels came out 0.03 lighter).
        t = time.time()
        run = subprocess.run([sys.executable, argv[3], args[0], "drape.png", "--shape", "drape", "--compare",
                              "--res", "64", "--samples", "4", "--no-denoise"], capture_output=True, text=True)
        assert run.returncode == 0, f"ptm_scene.py --shape drape --compare: exit {run.returncode}:\n{run.stderr[-2000:]}"
        with_ptm, without = (load_rgb("drape.with.png"), load_rgb("drape.without.png"))
        diff = [b - a for a, b in zip(with_ptm, without)]
        lightest = min(diff)
        mean = sum(diff) / len(diff)
        print(f"blender: drape --compare ({time.time() - t:.1f} s): without - with: mean {mean:.4f}, "
              f"lowest {lightest:+.4f} (the map darkens, never lightens)")
        assert lightest >= -2.0 / 255, f"the drape with the PTM is lighter than without by {-lightest:.4f} somewhere"
        assert mean > 0.005, f"the PTM darkens the drape by only {mean:.4f} on average: is it applied?"
    finally:
        os.chdir(cwd)


def main():
    os.makedirs(WORK, exist_ok=True)
    worst = {}
    t0 = time.time()
    mtlx_oso = compile_osl(os.path.abspath(MTLX_OSL))
    # The same shader generated without GenOptions.fileTextureVerticalFlip (MaterialX's default).
    noflip_oso = compile_osl(os.path.abspath(MTLX_OSL[:-4] + "_noflip.osl"))
    # ND_ptm_occlusion_learned_float's (mtlx_osl.py --learned).
    learned_oso = compile_osl(os.path.abspath(MTLX_OSL[:-4] + "_learned.osl"))
    flipped = {}
    print(f"blender: MaterialX-generated OSL ({open(MTLX_OSL).read().count(chr(10))} lines) compiled by Cycles' OSL compiler")
    for basis, link, uv in CASES:
        name = os.path.join(WORK, f"{basis}-{link}.ptm.exr")
        model = [] if basis.startswith("learned") else ["--link", link, "--uv", uv]
        subprocess.run([PTM, "bake", "--res", str(RES), "--spp", "4", "--dirs", "64", "--fit", basis,
                        *model, "--layout", "rgba", "-o", name],
                       check=True, capture_output=True)
        ref = json.loads(subprocess.run([EVAL, ptm_blender.stem_of(name) + ".c0.exr"]
                                        + [",".join(map(str, d)) for d in DIRS],
                                        check=True, capture_output=True, text=True).stdout)
        modes = ["osl", "nodes", "mtlx-osl"] + (["mtlx-osl-noflip"] if basis == "ptm11" else [])
        for mode in modes:
            sc, plane, sun = scene_setup()
            if mode.startswith("mtlx-osl"):
                oso = noflip_oso if mode.endswith("noflip") else (
                    learned_oso if basis.startswith("learned") else mtlx_oso)
                mat = mtlx_material(oso, ptm_blender.stem_of(name), basis, link, uv, sun)
            else:
                mat = ptm_blender.build_material(name, light="Key", mode=mode, output="k",
                                                 interpolation="Closest")
            plane.data.materials.append(mat)
            sc.cycles.shading_system = mode != "nodes"
            err = 0.0
            for i, d in enumerate(DIRS):
                aim(sun, d)
                got = render_k(sc, os.path.join(WORK, f"{basis}-{link}-{mode}-{i}.exr"))
                err = max(err, max(abs(got[r][c] - ref[i][r][c]) for r in range(RES) for c in range(RES)))
                spread = max(max(row) for row in ref[i]) - min(min(row) for row in ref[i])
                assert spread > 0.05 or not 0.1 < d[2] < 0.9, f"{basis} {link}: K is flat for light {d}; the test would prove nothing"
            if mode.endswith("noflip"):
                flipped[f"{basis} {link} {uv}"] = err
                print(f"blender: {basis} {link} {uv} {mode}: max |K - Ptm::eval| = {err:.2e}: rows upside down, "
                      "as expected without fileTextureVerticalFlip", flush=True)
                continue
            worst[f"{basis} {link} {uv} {mode}"] = err
            print(f"blender: {basis} {link} {uv} {mode}: max |K - Ptm::eval| = {err:.2e} over {len(DIRS)} lights", flush=True)
    # OSL's t = 0 is the file's top row, MaterialX's v = 0 its bottom: without the flip K must
    # be visibly wrong (else this test could not tell a flipped image from a right one).
    bad = {f"{k} mtlx-osl-noflip (expected > 0.05)": v for k, v in flipped.items() if not v > 0.05}
    # The README's Blender examples, run as written.
    readme = open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "docs", "pipeline.md")).read()
    block = readme.split("<!-- readme-blender -->\n```python\n", 1)[1].split("```", 1)[0]
    command = readme.split("<!-- readme-blender-scene -->\n```sh\n", 1)[1].split("```", 1)[0]
    readme_blender(block, command)
    worst["key-light occlusion, AOV K (output=lit)"], problems = key_light_only()
    bad.update({f"key-light occlusion: {p}": 1.0 for p in problems})
    worst["companion maps: AO (output=lit)"], problems = maps_lit()
    bad.update({f"companion maps: {p}": 1.0 for p in problems})
    bad.update({f"apply_material on a user's mesh: {p}": 1.0 for p in user_mesh()})
    worst["README OSL shader group (lit ratio)"] = readme_osl_group()
    bad.update({k: v for k, v in worst.items() if not v <= TOL})
    if LIT_PNG:
        sc, plane, sun = scene_setup()
        name = os.path.join(WORK, "lit.ptm.exr")
        subprocess.run([PTM, "bake", "--swatch", "builtin:twill", "--res", "64", "--spp", "8", "--dirs", "128",
                        "--fit", "ptm11", "--link", "logistic", "--uv", "hemispherical", "--layout", "rgba",
                        "-o", name], check=True, capture_output=True)
        bg = sc.world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bg.inputs["Strength"].default_value = 0.15
        plane.data.materials.append(ptm_blender.build_material(name, light="Key", mode="nodes",
                                                               output="lit", repeat=4.0))
        sun.data.energy = 3.0
        aim(sun, (0.8, 0.35, 0.45))
        sc.cycles.samples = 16
        sc.render.resolution_x = sc.render.resolution_y = 256
        sc.render.image_settings.file_format = "PNG"
        sc.render.image_settings.color_depth = "8"
        sc.render.filepath = os.path.abspath(LIT_PNG)
        bpy.ops.render.render(write_still=True)
        print(f"blender: lit example → {LIT_PNG}")
    print(f"blender: {len(worst)} configurations in {time.time() - t0:.1f} s; worst {max(worst.values()):.2e}")
    if bad:
        print(f"blender: FAILED (tolerance {TOL}): {bad}")
        sys.exit(1)


main()
