# `cargo xtask check-clients`: what Blender makes of a run's rigged avatar.glb.
#
# Run as: blender -b --python check_blender.py -- AVATAR.glb RENDER.png REPORT.json
# Imports the avatar, counts the armatures and their bones, rotates right_index1 by 45
# degrees and measures how far the right index finger's and the right thumb's vertices move,
# then renders the hands with Cycles from the training camera's side. Writes REPORT.json; the
# checks themselves are made by xtask, which reads it. With RENDER.png `-` nothing is
# rendered (the XR hands, xr/left.glb and xr/right.glb: only their armatures are checked).
import json
import math
import sys

import numpy

# Debian's Blender 3.4 ships with numpy 1.24, where `numpy.bool` is gone; its glTF importer
# still uses it.
numpy.bool = bool

import bpy  # noqa: E402
from mathutils import Quaternion, Vector  # noqa: E402

glb, png, report_path = sys.argv[sys.argv.index("--") + 1 :][:3]

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=glb)

armatures = [o for o in bpy.data.objects if o.type == "ARMATURE"]
meshes = {o.name: o for o in bpy.data.objects if o.type == "MESH"}
report = {
    "armatures": [
        {"name": a.name, "bones": sorted(b.name for b in a.data.bones)} for a in armatures
    ],
    "meshes": sorted(meshes),
}


def evaluated_vertices(obj):
    deps = bpy.context.evaluated_depsgraph_get()
    deps.update()
    ev = obj.evaluated_get(deps)
    m = ev.to_mesh()
    out = [ev.matrix_world @ v.co for v in m.vertices]
    ev.to_mesh_clear()
    return out


def group_vertices(obj, prefixes):
    """Vertices whose strongest vertex group is one of `prefixes`' bones."""
    names = {g.index: g.name for g in obj.vertex_groups}
    chosen = []
    for v in obj.data.vertices:
        if not v.groups:
            continue
        best = max(v.groups, key=lambda g: g.weight)
        if any(names[best.group].startswith(p) for p in prefixes):
            chosen.append(v.index)
    return chosen


right = next((o for n, o in meshes.items() if n.startswith("right_hand")), None)
rig = next((a for a in armatures if "right_index1" in a.data.bones), None)
if right is not None and rig is not None:
    index = group_vertices(right, ["right_index"])
    thumb = group_vertices(right, ["right_thumb"])
    before = evaluated_vertices(right)
    bone = rig.pose.bones["right_index1"]
    bone.rotation_mode = "QUATERNION"
    bone.rotation_quaternion = bone.rotation_quaternion @ Quaternion(
        Vector((1.0, 0.0, 0.0)), math.radians(45.0)
    )
    after = evaluated_vertices(right)
    moved = [(after[i] - before[i]).length for i in range(len(before))]
    report["index_vertices"] = len(index)
    report["thumb_vertices"] = len(thumb)
    report["index_moved_max_m"] = max((moved[i] for i in index), default=0.0)
    report["thumb_moved_max_m"] = max((moved[i] for i in thumb), default=0.0)
    # Back to the input pose for the render.
    bone.rotation_quaternion = bone.rotation_quaternion @ Quaternion(
        Vector((1.0, 0.0, 0.0)), math.radians(-45.0)
    )

# Render: a camera on the training camera's side (the glTF frame's camera looks down -Z,
# Blender's import turns that into +Y), framing both hands.
points = [p for o in meshes.values() for p in evaluated_vertices(o)] if png != "-" else []
if points:
    lo = Vector((min(p.x for p in points), min(p.y for p in points), min(p.z for p in points)))
    hi = Vector((max(p.x for p in points), max(p.y for p in points), max(p.z for p in points)))
    center = (lo + hi) / 2
    radius = max((p - center).length for p in points)
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 50.0
    cam = bpy.data.objects.new("camera", cam_data)
    bpy.context.scene.collection.objects.link(cam)
    direction = center.normalized() if center.length > 1e-6 else Vector((0.0, 1.0, 0.0))
    # The vertical field of view of a 4:3 frame (the sensor's 36 mm spans its width).
    fov = 2 * math.atan(36.0 * 3 / 4 / 2 / cam_data.lens)
    distance = radius / math.tan(fov / 2) * 1.1
    cam.location = center - direction * distance
    cam.rotation_mode = "QUATERNION"
    cam.rotation_quaternion = direction.to_track_quat("-Z", "Y")
    bpy.context.scene.camera = cam
    sun_data = bpy.data.lights.new("key", type="SUN")
    sun_data.energy = 3.0
    sun = bpy.data.objects.new("key", sun_data)
    sun.rotation_mode = "QUATERNION"
    sun.rotation_quaternion = (direction + Vector((0.3, 0.0, -0.6))).normalized().to_track_quat(
        "-Z", "Y"
    )
    bpy.context.scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs[0].default_value = (0.55, 0.57, 0.6, 1.0)
    world.node_tree.nodes["Background"].inputs[1].default_value = 0.6
    bpy.context.scene.world = world
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 32
    # Debian's build has no OpenImageDenoise.
    scene.cycles.use_denoising = False
    scene.render.resolution_x = 640
    scene.render.resolution_y = 480
    scene.render.filepath = png
    bpy.ops.render.render(write_still=True)
    report["render"] = png

with open(report_path, "w") as f:
    json.dump(report, f, indent=1)
