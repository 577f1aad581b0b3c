"""Export a Motion: BVH on the 22-joint rig (for Blender and other tools), binary glTF (.glb:
physmotion.io.gltf) and our .npz."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.io.bvh import WRITE_ORDER, write_bvh
from physmotion.io.rigs import RigMotion
from physmotion.motion import Motion
from physmotion.paths import MOTION_SUFFIXES
from physmotion.skeleton import JOINT_NAMES, PARENTS, inverse_kinematics, offsets_from_joints


def save_bvh(motion: Motion, path: str | Path, *, order: str = WRITE_ORDER) -> None:
    """Write ``motion`` as BVH on the 22-joint SMPL rig, atomically.

    Joints and hierarchy: :data:`physmotion.skeleton.JOINT_NAMES` / ``PARENTS``; offsets from
    :func:`skeleton.offsets_from_joints` (T-pose rest), local rotations from
    :func:`skeleton.inverse_kinematics` written as intrinsic Euler angles in ``order`` (default
    ``YZX``: see :data:`physmotion.io.bvh.WRITE_ORDER`). Units are metres and Y is up, so Blender's
    default BVH import (forward -Z, up Y, scale 1) gives a body of the right size standing upright;
    the frame time is ``1 / motion.fps``. Re-import with ``import_clip(path, rig="smpl22")``.
    """
    joints = np.asarray(motion.joints, dtype=np.float64)
    offsets = offsets_from_joints(joints)
    rotations, root = inverse_kinematics(joints, offsets)
    translations = np.broadcast_to(offsets, joints.shape).copy()
    translations[:, 0] = root
    rig = RigMotion(
        names=JOINT_NAMES, parents=np.array(PARENTS), rotations=rotations, translations=translations
    )
    write_bvh(path, rig, motion.fps, order=order)


def save_npz(motion: Motion, path: str | Path) -> None:
    """Write ``motion`` as our .npz (joints, rotations, offsets, fps, texts, licence), atomically."""
    motion.save(path)


def save_motion(motion: Motion, path: str | Path) -> None:
    """Write ``motion`` in the format its suffix names: ``.bvh``, ``.glb`` or ``.npz``."""
    suffix = Path(path).suffix.lower()
    if suffix == ".bvh":
        save_bvh(motion, path)
    elif suffix == ".glb":
        from physmotion.io.gltf import save_glb  # pygltflib is imported only for a .glb

        save_glb(motion, path)
    elif suffix == ".npz":
        save_npz(motion, path)
    else:
        formats = " or ".join(MOTION_SUFFIXES)
        raise PhysmotionError(f"{path}: unknown output format {suffix or '(none)'!r}: use {formats}")


def export_file(source: str | Path, out: str | Path, *, rig_from: str | Path | None = None, rig: str | None = None,
                mapping: str | Path | None = None, units: str | None = None, in_place: bool = False,
                loop: bool = False) -> list[str]:  # fmt: skip
    """``physmotion export``: the motion in ``source`` (.npz) written to ``out`` by its suffix, optionally
    trimmed to its best loop (``loop``), without its horizontal travel (``in_place``) and retargeted onto
    the skeleton of the BVH ``rig_from`` (its rig table ``rig`` or ``mapping``, ``units``; the output must
    then be a .bvh). Every option is checked before the motion is read. Returns the lines to report."""
    from physmotion.io.in_place import best_loop, trim_to_loop
    from physmotion.io.in_place import in_place as remove_travel

    out = Path(out)
    if (rig or mapping or units) and rig_from is None:
        raise PhysmotionError("--rig, --mapping and --units need --rig-from THEIR.bvh")
    if rig_from is not None and out.suffix.lower() != ".bvh":
        raise PhysmotionError(f"--rig-from writes a .bvh, not {out.suffix or out.name!r}")
    target = None
    if rig_from is not None:
        from physmotion.io.retarget_rig import load_target

        target = load_target(rig_from, rig=rig, mapping=mapping, units=units)
    motion, lines = Motion.load(source), []
    if loop:
        found = best_loop(motion.joints)
        motion = trim_to_loop(motion, found)
        lines.append(f"loop: frames {found.start}..{found.end - 1}, pose distance {100 * found.distance:.1f} cm")
    if in_place:
        motion = remove_travel(motion)
    if target is None:
        save_motion(motion, out)
        return [*lines, f"wrote {out}"]
    from physmotion.io.retarget_rig import save_retargeted_bvh

    result = save_retargeted_bvh(motion, out, target)
    return [*lines, f"wrote {out}: {len(target.rest.names)} joints of {Path(rig_from).name} ({target.table.name}), "
                    f"leg ratio {result.leg_ratio:.2f}"]  # fmt: skip
