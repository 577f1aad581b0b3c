"""Import of real motion capture (BVH, ASF/AMC; any rig, unit, up axis, rate) and export.

    clips = load_manifest(mocap_dir)          # the rows of shared/data/mocap/manifest.csv
    motion = import_clip(clips[0])            # canonical Motion: 22 joints, metres, Y up, 20 fps
    motion = import_clip("my.bvh", mapping={...}, units="cm", fps=60)   # a user's own rig
    motion = import_clip("my.bvh", mapping="map.json")                  # ... described in a file
    save_bvh(motion, "out.bvh"); save_npz(motion, "out.npz")

Modules: ``bvh`` (BVH reader/writer; a file that is not UTF-8 is read as Latin-1 with a warning),
``amc`` (ASF/AMC reader), ``rigs`` (generic rig tree and per-rig tables, Mixamo's among them),
``mapping`` (a user's rig as a JSON file), ``canonical`` (to the project's conventions), ``floor``
(where the motion meets the floor), ``importer``, ``export``.
"""

from physmotion.io.export import save_bvh, save_motion, save_npz
from physmotion.io.importer import ClipInfo, ImportReport, import_clip, import_clip_with_report, load_manifest
from physmotion.io.rigs import RIGS, RigMotion, RigTable, table_from_mapping

__all__ = [
    "RIGS",
    "ClipInfo",
    "ImportReport",
    "RigMotion",
    "RigTable",
    "import_clip",
    "import_clip_with_report",
    "load_manifest",
    "save_bvh",
    "save_motion",
    "save_npz",
    "table_from_mapping",
]
