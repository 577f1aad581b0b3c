"""Run inside Blender (not by pytest): open one exported motion file and report what Blender sees.

``blender --background --factory-startup --python-exit-code 1 --python tests/blender_open.py -- REQUEST.json``
with REQUEST a JSON object: ``path`` (the file), ``importer`` (Python run here with ``bpy`` and ``path``
in scope, e.g. ``bpy.ops.import_anim.bvh(filepath=path)``), ``bones`` (bone names whose world head
positions to report) and ``frames`` (0-based motion frames to report them at); ``out``: where the JSON
answer goes: the armature's bone count, the scene's frame rate, the action's frame range and keyframe
count, and per bone the head positions, converted back to our Y-up axes.
tests/test_blender.py writes the request and checks the answer.
"""

import builtins
import json
import sys

import bpy

request = json.loads(open(sys.argv[sys.argv.index("--") + 1], encoding="utf-8").read())

# Debian's Blender 3.4.1 runs on Python 3.11, which no longer accepts open()'s "U" mode ("What's New In
# Python 3.11", Porting: open() no longer accepts 'U'), but its BVH importer still opens files with
# 'rU' (io_anim_bvh/import_bvh.py, read_bvh) and fails with "invalid mode: 'rU'". Give that module an
# open() that drops the flag (text mode reads universal newlines anyway).
import io_anim_bvh.import_bvh as _import_bvh  # noqa: E402

_import_bvh.open = lambda file, mode="r", *a, **k: builtins.open(file, mode.replace("U", ""), *a, **k)

# Its glTF importer needs numpy (Debian's python3-numpy, installed beside blender by `make blender`) and
# still spells numpy's bool np.bool (io_scene_gltf2/blender/imp/gltf2_blender_mesh.py, set_poly_smoothing),
# an alias numpy 1.24 removed ("NumPy 1.24 Release Notes", expired deprecations): restore that alias.
try:
    import numpy as _np  # noqa: E402

    if "bool" not in _np.__dict__:
        _np.bool = bool
except ImportError:  # the BVH importer does without numpy
    pass

scene = bpy.context.scene
before = set(bpy.data.objects)
exec(request["importer"], {"bpy": bpy, "path": request["path"]})
armatures = [o for o in bpy.data.objects if o not in before and o.type == "ARMATURE"]
if len(armatures) != 1:
    raise SystemExit(f"expected one armature from {request['path']}, got {len(armatures)}")
arm = armatures[0]
action = arm.animation_data.action
first, last = action.frame_range
answer = {
    "bones": len(arm.data.bones),
    "fps": scene.render.fps / scene.render.fps_base,
    "frame_range": [first, last],
    "keyframes": max(len(c.keyframe_points) for c in action.fcurves),
    "heads": {},
}
for name in request["bones"]:
    heads = []
    for k in request["frames"]:
        scene.frame_set(int(round(first)) + k)  # the action's first frame is the motion's frame 0
        x, y, z = arm.matrix_world @ arm.pose.bones[name].head
        heads.append([x, z, -y])  # Blender's Z up, -Y forward back to our Y up, +Z forward
    answer["heads"][name] = heads
with open(request["out"], "w", encoding="utf-8") as f:
    json.dump(answer, f)
