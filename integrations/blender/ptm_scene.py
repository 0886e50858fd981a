"""Renders an occlusion PTM in Blender (Cycles) from nothing: a fresh scene, a key sun, a world
fill, a plane or a UV sphere with the PTM tiled over its UVs, a camera, and the material of
ptm_blender.py with the occlusion confined to the key light. One command, headless:

    blender --background --python integrations/blender/ptm_scene.py -- w.ptm.c0.exr out.png
    python integrations/blender/ptm_scene.py w.ptm.c0.exr out.png     # PyPI bpy 5.0 (.deps/bpy)

Options (after the two paths): --shape plane|sphere|drape (drape: a cloth simulated over a ball,
on a floor), --repeat N or X,Y (tiles across the UV square),
--light ELEV,AZIM (degrees, the key sun's direction), --energy W (sun strength), --world S
(grey world strength: the fill that K must not darken), --samples N, --res N (square image),
--mode nodes|osl, --output lit|multiply (see ptm_blender.py), --albedo R,G,B, --no-ptm (the same
render without the occlusion), --compare (both side by side in one image: without | with),
--no-denoise, --no-maps (leave out the normal and AO maps that `ptm bake --maps --maps-png`
wrote beside the PTM: NAME.normal.png, NAME.ao.png, used when present),
--blend FILE (also save the .blend).
"""
import argparse
import math
import os
import sys

import bpy
import mathutils

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import ptm_blender  # noqa: E402


def parse(argv):
    ap = argparse.ArgumentParser(prog="ptm_scene.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("ptm", help="the PTM in the renderer layout: NAME.ptm.c0.exr (or NAME.ptm.exr)")
    ap.add_argument("out", help="the image to write (PNG)")
    ap.add_argument("--shape", choices=("plane", "sphere", "drape"), default="plane")
    ap.add_argument("--repeat", help="tiles across the UV square: N or ACROSS,DOWN "
                    "(default 4 on the plane, 16,8 on the sphere, whose UV map spans 2π × π, "
                    "16 on the drape)")
    ap.add_argument("--light", default="35,30", help="key sun elevation,azimuth in degrees")
    ap.add_argument("--energy", type=float, default=3.0)
    ap.add_argument("--world", type=float, default=0.15)
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--mode", choices=("nodes", "osl"), default="nodes")
    ap.add_argument("--output", choices=("lit", "multiply"), default="lit")
    ap.add_argument("--albedo", default="0.8,0.7,0.6")
    ap.add_argument("--no-ptm", action="store_true")
    ap.add_argument("--compare", action="store_true")
    ap.add_argument("--no-denoise", action="store_true", help="leave Cycles' denoiser off")
    ap.add_argument("--no-maps", action="store_true",
                    help="leave out the normal and AO maps found beside the PTM (ptm bake --maps --maps-png)")
    ap.add_argument("--blend")
    args = ap.parse_args(argv)
    try:
        elev, azim = (math.radians(float(x)) for x in args.light.split(","))
    except ValueError:
        ap.error(f"--light {args.light!r}: two numbers in degrees, elevation,azimuth (e.g. 35,30)")
    if not 0.0 < elev <= math.pi / 2:
        ap.error(f"--light {args.light!r}: elevation must be in (0, 90] degrees")
    args.light_dir = (math.cos(elev) * math.cos(azim), math.cos(elev) * math.sin(azim), math.sin(elev))
    try:
        args.albedo = tuple(float(x) for x in args.albedo.split(",")) + (1.0,)
        assert len(args.albedo) == 4
    except (ValueError, AssertionError):
        ap.error(f"--albedo {args.albedo!r}: three numbers, R,G,B")
    try:
        default = {"plane": "4", "sphere": "16,8", "drape": "16"}[args.shape]
        rep = [float(x) for x in (args.repeat or default).split(",")]
        assert len(rep) in (1, 2) and all(r > 0 for r in rep)
        args.repeat = (rep[0], rep[-1])
    except (ValueError, AssertionError):
        ap.error(f"--repeat {args.repeat!r}: one or two positive numbers, N or ACROSS,DOWN")
    if not os.path.exists(ptm_blender.stem_of(args.ptm) + ".c0.exr"):
        ap.error(f"{ptm_blender.stem_of(args.ptm)}.c0.exr not found (from {args.ptm}): write the PTM in "
                 "the renderer layout with `ptm fit … --layout rgba` or `ptm convert IN -o OUT --layout rgba`")
    return args


def aim(obj, d):
    """Points the object's +Z axis along d (a sun shines along its −Z)."""
    obj.rotation_euler = mathutils.Vector(d).normalized().to_track_quat("Z", "Y").to_euler()


def drape(sc):
    """A square cloth (48² quads, its UVs the unit square) dropped on a ball of radius 0.7 by
    Blender's cloth simulation (40 frames, about 10 s), frozen into a mesh, subdivided and
    smooth shaded; the ball and a floor stay in the scene. Leaves the cloth active."""
    bpy.ops.mesh.primitive_plane_add(size=12.0, location=(0.0, 0.0, -0.72))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=0.7)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.active_object
    ball.modifiers.new("collision", "COLLISION")
    ball.collision.thickness_outer = 0.02
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=48, y_subdivisions=48, size=2.6, location=(0.0, 0.0, 0.8))
    cloth = bpy.context.active_object
    sim = cloth.modifiers.new("cloth", "CLOTH")
    sim.settings.quality = 5
    sim.collision_settings.distance_min = 0.01
    sim.point_cache.frame_end = 40
    for f in range(1, 41):
        sc.frame_set(f)
    frozen = bpy.data.meshes.new_from_object(cloth.evaluated_get(bpy.context.evaluated_depsgraph_get()))
    cloth.modifiers.clear()
    cloth.data = frozen
    cloth.modifiers.new("subdivision", "SUBSURF").levels = 1
    cloth.modifiers["subdivision"].render_levels = 2
    bpy.ops.object.shade_smooth()
    sc.frame_set(1)


def build_scene(args):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = args.samples
    sc.cycles.use_denoising = not args.no_denoise
    sc.render.resolution_x = sc.render.resolution_y = args.res
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("fill")
    if world.node_tree is None:  # Blender < 5.0
        world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bg.inputs["Strength"].default_value = args.world
    sc.world = world
    if args.shape == "plane":
        bpy.ops.mesh.primitive_plane_add(size=2.0)
        cam_at, cam_from = (0.0, 0.0, 0.0), (0.0, -3.2, 2.6)
    elif args.shape == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
        bpy.ops.object.shade_smooth()
        cam_at, cam_from = (0.0, 0.0, 0.0), (0.0, -3.6, 1.4)
    else:
        drape(sc)
        cam_at, cam_from = (0.0, 0.0, -0.05), (0.0, -4.4, 2.3)
    obj = bpy.context.active_object
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    cam.location = cam_from
    cam.rotation_euler = (mathutils.Vector(cam_at) - mathutils.Vector(cam_from)).to_track_quat("-Z", "Y").to_euler()
    sc.camera = cam
    key = bpy.data.objects.new("Key", bpy.data.lights.new("Key", "SUN"))
    key.data.energy = args.energy
    key.data.angle = math.radians(0.5)
    sc.collection.objects.link(key)
    aim(key, args.light_dir)
    bpy.context.view_layer.update()
    plain = bpy.data.materials.new("no PTM")
    if plain.node_tree is None:  # Blender < 5.0
        plain.use_nodes = True
    plain.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = args.albedo
    if args.no_ptm:
        mat = plain
    else:
        mat = ptm_blender.build_material(args.ptm, light=key, mode=args.mode, output=args.output,
                                         albedo=args.albedo, repeat=args.repeat, scene=sc,
                                         maps=None if args.no_maps else "auto")
    obj.data.materials.append(mat)
    return sc, obj, plain


def side_by_side(left, right, out):
    """Writes PNG `out`: image file `left` | image file `right` (same size)."""
    import numpy as np

    imgs = [bpy.data.images.load(p) for p in (left, right)]
    w, h = imgs[0].size
    px = []
    for img in imgs:
        a = np.empty(w * h * 4, dtype=np.float32)
        img.pixels.foreach_get(a)
        px.append(a.reshape(h, w, 4))
    both = bpy.data.images.new("compare", 2 * w, h)
    both.pixels.foreach_set(np.concatenate(px, axis=1).ravel())
    both.filepath_raw = out
    both.file_format = "PNG"
    both.save()
    for img in imgs + [both]:
        bpy.data.images.remove(img)


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    args = parse(argv)
    sc, obj, plain = build_scene(args)
    sc.render.image_settings.file_format = "PNG"
    out = os.path.abspath(args.out)
    if args.blend:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.blend))
    what = "without the PTM" if args.no_ptm else f"PTM {os.path.basename(ptm_blender.stem_of(args.ptm))}"
    if args.compare and not args.no_ptm:
        with_ptm = out[:-4] + ".with.png" if out.endswith(".png") else out + ".with.png"
        without = with_ptm[:-9] + ".without.png"
        sc.render.filepath = with_ptm
        bpy.ops.render.render(write_still=True)
        obj.data.materials[0] = plain  # the compositor stays: with no AOV written it passes the image
        sc.render.filepath = without
        bpy.ops.render.render(write_still=True)
        side_by_side(without, with_ptm, out)
        what = f"without | with {what}"
    else:
        sc.render.filepath = out
        bpy.ops.render.render(write_still=True)
    print(f"ptm_scene: {args.shape}, {what}, key sun at {args.light}° → {out}")


main()
