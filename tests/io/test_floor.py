"""The import floor (physmotion/io/floor.py): least Penetrate + Float over the frames where a foot or hand stands.

Measured with the metrics' own measure: ``physmotion metrics``'s humanoid surface on the saved joints.
"""

from __future__ import annotations

import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physmotion.errors import PhysmotionError
from physmotion.io import ClipInfo, import_clip, import_clip_with_report, save_bvh
from physmotion.io.floor import (
    UnevenGroundWarning,
    best_floor,
    floor_tilt,
    ground,
    hand_frames,
    stance_frames,
)
from physmotion.metrics.physical import penetrate
from physmotion.motion import Motion
from physmotion.physics.surface import HumanoidSurface


def _penetrate(joints: np.ndarray, fps: float) -> float:
    """Penetrate (mm) as `physmotion metrics` measures a saved motion: humanoid surface, float32 joints."""
    return float(penetrate(np.asarray(joints, dtype=np.float32).astype(np.float64), fps, body=HumanoidSurface()))


def test_best_floor_is_exact() -> None:
    """The floor minimises Penetrate (every frame) + Float (contact frames) with the metrics' 5 mm
    tolerance: no floor on a fine grid does better, and a shift of the heights shifts it alike."""
    rng = np.random.default_rng(0)
    for n in (1, 2, 7, 200):
        low = rng.normal(0.0, 0.03, n)
        contact = rng.random(n) < 0.6
        contact[0] = True

        def cost(f: float, low: np.ndarray = low, contact: np.ndarray = contact) -> float:
            return float(np.maximum(f - 0.005 - low, 0).sum() + np.maximum(low[contact] - 0.005 - f, 0).sum())

        f = best_floor(low, contact)
        assert cost(f) <= min(cost(g) for g in np.linspace(-0.2, 0.2, 4001)) + 1e-12
        assert best_floor(low + 0.3, contact) == pytest.approx(f + 0.3, abs=1e-12)


def test_one_low_frame_does_not_lift_the_clip() -> None:
    """The rule this replaced capped Penetrate at 1.5 mm and so lifted a whole clip for a few low frames
    (Float 13.8 mm over all clips); now a few deep frames weigh less than the standing ones."""
    low = np.zeros(100)
    low[:3] = -0.2  # three frames 20 cm down (a body lying lower than its feet stood)
    # the soles 5 mm up (the tolerance): Float 0, and the deep frames 5 mm less deep
    assert best_floor(low, np.ones(100, dtype=bool)) == pytest.approx(-0.005, abs=1e-12)


def test_grounding_moves_with_the_motion(clip) -> None:
    """Any vertical offset in, the same motion out; a grounded motion is left where it is."""
    joints = import_clip(clip("bandai2_dataset-2_walk_normal_001")).joints.astype(np.float64)
    for offset in (0.0, 0.31, -0.12):
        out, g = ground(joints + [0.0, offset, 0.0])
        assert np.abs(out - joints).max() < 1e-6 and g.lift == pytest.approx(-offset, abs=1e-6)


def test_stance_frames_of_hops(hdm05_manifest: list[ClipInfo]) -> None:
    """HDM05's hops: stance frames (take-off, landing) low, flight frames not stance; a hop cut from
    take-off to landing has none and puts its lowest point over the clip on the floor."""
    with_stance = without = 0
    for info in (c for c in hdm05_manifest if "hopBothLegs" in c.clip):
        clip_id = info.clip
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Latin-1 headers
            motion, report = import_clip_with_report(info)
        stance = stance_frames(motion.joints)
        feet = motion.joints[:, [7, 10, 8, 11], 1].min(axis=-1)  # lowest foot joint per frame
        assert not stance.all(), clip_id
        if stance.any():
            with_stance += 1
            assert feet[stance].max() < feet.max() - 0.1, clip_id  # the flight's top is never stance
        else:
            without += 1
            lowest = HumanoidSurface().lowest_height(motion.joints.astype(np.float64))
            if report.grounding.stance_share == 0:  # no foot or hand stands: the lowest point on the floor
                assert lowest.min() == pytest.approx(0.0, abs=1e-5)
    assert with_stance and without  # both kinds are in the data


def _floor_slope(joints: np.ndarray) -> float:
    """Rise per metre of the body's lowest point over the stance frames, along the clip's main direction
    of travel: a straight line fitted by numpy (not floor_tilt's plane)."""
    x = joints.astype(np.float64)
    stance = stance_frames(x)
    root = x[stance][:, 0, [0, 2]]
    along = (root - root.mean(axis=0)) @ np.linalg.svd(root - root.mean(axis=0), full_matrices=False)[2][0]
    return float(np.polyfit(along, HumanoidSurface().lowest_height(x)[stance], 1)[0])


def test_a_tilted_capture_floor_is_levelled(clip) -> None:
    """CMU subject 7's walks stand on a floor rising about 1.9 cm a metre along the walk (1.1 degrees;
    Penetrate 9.5 mm and the standing frames up to 4.6 cm over a level floor on this take). The import
    turns the clip so that floor is level; a second levelling finds nothing to do."""
    motion, report = import_clip_with_report(clip("cmuiclone_07_04"))
    assert 0.8 < report.grounding.tilt < 1.4
    assert abs(_floor_slope(motion.joints)) < 0.003  # 0.019 before the levelling
    assert np.array_equal(floor_tilt(motion.joints), np.eye(3))
    assert _penetrate(motion.joints, motion.fps) < 4.0  # 9.5 mm before


def test_a_known_tilt_is_undone_and_a_level_floor_left(clip) -> None:
    """A Bandai walk (a level floor: left as captured) tilted by 1.5 degrees about its sideways axis: the
    rotation found undoes it to 0.1 degrees. Standing in place, nothing is measured."""
    motion, report = import_clip_with_report(clip("bandai2_dataset-2_walk_normal_001"))
    joints = motion.joints.astype(np.float64)
    assert report.grounding.tilt == 0.0 and np.array_equal(floor_tilt(joints), np.eye(3))
    tilt = Rotation.from_euler("x", 1.5, degrees=True)
    found = Rotation.from_matrix(floor_tilt(joints @ tilt.as_matrix().T))
    assert np.degrees((found * tilt).magnitude()) < 0.1
    still = np.repeat(joints[:1], 60, axis=0)  # one standing frame held for 3 s
    assert np.array_equal(floor_tilt(still @ tilt.as_matrix().T), np.eye(3))


def _every_clip(import_results, hdm05_results) -> dict[str, tuple[str, Motion, object]]:
    out: dict[str, tuple[str, Motion, object]] = {}
    for results in (import_results, hdm05_results):
        for k, v in results.items():
            if isinstance(v, tuple):
                out[k] = (v[0].source, v[0], v[1])
    return out


def test_a_walk_over_uneven_ground_is_named(clip) -> None:
    """CMU's "walk on uneven terrain" stands at heights about 24 cm apart: no level floor fits it, and the
    import says so in one warning naming the file; a walk on level ground (Bandai) imports silently."""
    with pytest.warns(UnevenGroundWarning, match=r"03_01\.amc: the body stands at heights \d+ cm apart"):
        _, uneven = import_clip_with_report(clip("cmu_03_01"))
    assert not uneven.grounding.level and uneven.grounding.stance_spread > 0.2
    assert uneven.grounding.tilt == 0.0  # steps up and down are not a tilted floor
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnevenGroundWarning)
        _, level = import_clip_with_report(clip("bandai2_dataset-2_walk_normal_001"))
    assert level.grounding.level and level.grounding.stance_spread < 0.05


@pytest.mark.slow
def test_only_clips_captioned_uneven_stand_on_uneven_ground(manifest, hdm05_manifest, import_results,
                                                           hdm05_results) -> None:  # fmt: skip
    """Over every clip of both collections, the clips found not level are those whose captions say the
    ground is uneven (CMU subject 3, as AMC and as iClone BVH), and only those."""
    captions = {c.clip: " ".join(c.captions) for c in [*manifest, *hdm05_manifest]}
    found = {k for k, (_, _, report) in _every_clip(import_results, hdm05_results).items()
             if not report.grounding.level}  # fmt: skip
    assert found == {k for k, text in captions.items() if "uneven" in text} and len(found) == 4


@pytest.mark.slow
def test_captured_clips_come_in_on_their_best_floor(manifest, hdm05_manifest, import_results, hdm05_results) -> None:
    """Every clip of every source, on the saved float32 joints: the floor is where Penetrate + Float over
    the contact frames is least (a clip with no contact frame: its lowest point)."""
    sources = {c.clip: c.source for c in [*manifest, *hdm05_manifest]}
    per_source: dict[str, list[float]] = defaultdict(list)
    for clip_id, (_, motion, _report) in _every_clip(import_results, hdm05_results).items():
        joints = motion.joints.astype(np.float64)
        per_source[sources[clip_id]].append(_penetrate(motion.joints, motion.fps))
        surface = HumanoidSurface()
        lowest = surface.lowest_height(joints)
        contact = stance_frames(joints) | hand_frames(joints, surface.hand_heights(joints), lowest)
        floor = best_floor(lowest, contact) if contact.any() else lowest.min()
        assert abs(floor) < 1e-5, clip_id
    assert set(per_source) == set(sources.values())  # every source imported
    for source, values in sorted(per_source.items()):
        print(f"\n{source}: {len(values)} clips, Penetrate mean {np.mean(values):.2f} max {np.max(values):.2f} mm",
              end="")  # fmt: skip


def _sample(manifest: list[ClipInfo]) -> list[ClipInfo]:
    """The first clip of each source and skeleton, and the first of each HDM05 class (a hop, a lie-down)."""
    seen: dict[tuple[str, str], ClipInfo] = {}
    for c in manifest:
        key = (c.source, c.skeleton if c.format == "bvh" else c.path.parent.name)
        seen.setdefault(key, c)
    return list(seen.values())


@pytest.mark.slow
def test_export_import_round_trip_within_1mm(manifest, hdm05_manifest, tmp_path: Path) -> None:
    """A clip of every source and rig (and every HDM05 class): import, export to BVH, import again."""
    worst: dict[str, float] = {}
    for info in _sample([*manifest, *hdm05_manifest]):
        motion = import_clip(info)
        path = tmp_path / f"{info.clip}.bvh"
        save_bvh(motion, path)
        back, report = import_clip_with_report(path)
        assert report.rig == "smpl22" and back.num_frames == motion.num_frames
        worst[info.clip] = float(np.linalg.norm(back.joints - motion.joints, axis=-1).max())
    clip = max(worst, key=worst.get)
    print(f"\nround trip over {len(worst)} clips: max {worst[clip] * 1000:.4f} mm ({clip})")
    assert worst[clip] < 1e-3


def test_the_rule_before_is_kept_for_p(clip) -> None:
    """``floor="frame0"`` (P's input convention): frame 0's lowest foot joint on y = 0, the same motion
    otherwise; an unknown floor is a one-line error."""
    info = clip("bandai1_dataset-1_dash_proud_001")
    stance, frame0 = import_clip(info), import_clip(info, floor="frame0")
    assert abs(frame0.joints[0, [7, 8, 10, 11], 1].min()) < 1e-6
    shift = stance.joints - frame0.joints
    assert np.abs(shift[..., [0, 2]]).max() < 1e-5 and np.ptp(shift[..., 1]) < 1e-5
    with pytest.raises(PhysmotionError, match="floor must be one of stance, frame0"):
        import_clip(info, floor="joints")


def test_a_flat_hand_reaches_down_by_its_thickness(clip) -> None:
    """The surface's hand is flat: its lowest point is the wrist less the hand box's half thickness, not
    PHC's box 19 cm out along the forearm (which lifted hand-supported clips 10-20 cm at import)."""
    joints = import_clip(clip("cmuiclone_05_06")).joints.astype(np.float64)  # a cartwheel
    surface = HumanoidSurface()
    hands = surface.hand_heights(joints)  # (T, 2)
    drop = joints[:, [20, 21], 1] - hands
    assert np.allclose(drop, drop[0, 0], atol=1e-5) and 0.01 < drop[0, 0] < 0.02  # the retargeted wrist: 1e-7 m
    assert np.all(surface.lowest_height(joints) <= hands.min(axis=-1) + 1e-12)
