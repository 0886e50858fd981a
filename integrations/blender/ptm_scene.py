"""Renders an occlusion PTM in Blender (Cycles) from nothing: a fresh scene, a key sun, a world
fill, a plane or a UV sphere with the PTM tiled over its UVs, a camera, and the material of
ptm_blender.py with the occlusion confined to the key light. One command, headless:

    blender --background --python integrations/blender/ptm_scene.py -- w.ptm.c0.exr out.png
    python integrations/blender/ptm_scene.py w.ptm.c0.exr out.png     # PyPI bpy 5.0 (.deps/bpy)

Options (after the two paths): --shape plane|sphere, --repeat N or X,Y (tiles across the UV square),
--light ELEV,AZIM (degrees, the key sun's direction), --energy W (sun strength), --world S
(grey world strength: the fill that K must not darken), --samples N, --res N (square image),
--mode nodes|osl, --output lit|multiply (see ptm_blender.py), --albedo R,G,B, --no-ptm (the same
render without the occlusion, to compare), --blend FILE (also save the .blend).
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
    ap.add_argument("--shape", choices=("plane", "sphere"), default="plane")
    ap.add_argument("--repeat", help="tiles across the UV square: N or ACROSS,DOWN "
                    "(default 4 on the plane, 16,8 on the sphere, whose UV map spans 2π × π)")
    ap.add_argument("--light", default="35,30", help="key sun elevation,azimuth in degrees")
    ap.add_argument("--energy", type=float, default=3.0)
    ap.add_argument("--world", type=float, default=0.15)
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--mode", choices=("nodes", "osl"), default="nodes")
    ap.add_argument("--output", choices=("lit", "multiply"), default="lit")
    ap.add_argument("--albedo", default="0.8,0.7,0.6")
    ap.add_argument("--no-ptm", action="store_true")
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
        rep = [float(x) for x in (args.repeat or ("4" if args.shape == "plane" else "16,8")).split(",")]
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


def build_scene(args):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = args.samples
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
    else:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
        bpy.ops.object.shade_smooth()
        cam_at, cam_from = (0.0, 0.0, 0.0), (0.0, -3.6, 1.4)
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
    if args.no_ptm:
        mat = bpy.data.materials.new("no PTM")
        if mat.node_tree is None:  # Blender < 5.0
            mat.use_nodes = True
        mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = args.albedo
    else:
        mat = ptm_blender.build_material(args.ptm, light=key, mode=args.mode, output=args.output,
                                         albedo=args.albedo, repeat=args.repeat, scene=sc)
    obj.data.materials.append(mat)
    return sc


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    args = parse(argv)
    sc = build_scene(args)
    sc.render.image_settings.file_format = "PNG"
    sc.render.filepath = os.path.abspath(args.out)
    if args.blend:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.blend))
    bpy.ops.render.render(write_still=True)
    what = "without the PTM" if args.no_ptm else f"PTM {os.path.basename(ptm_blender.stem_of(args.ptm))}"
    print(f"ptm_scene: {args.shape}, {what}, key sun at {args.light}° → {sc.render.filepath}")


main()
