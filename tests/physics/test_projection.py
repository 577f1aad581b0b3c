"""The projection P on real mocap: what it does today (see the physics issue's note for what it
does not do yet: the all-clips targets are measured by experiments/projection_quality.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from physmotion.errors import ShapeError
from physmotion.features.humanml3d import extract_features
from physmotion.metrics import physical_metrics
from physmotion.metrics.dynamics import largest_step
from physmotion.physics.humanoid import body_from_joints
from physmotion.physics.projection import ProjectionConfig, prepare_motion, project, resample_qpos
from physmotion.physics.retarget import qpos_to_joints
from physmotion.physics.surface import HumanoidSurface

from .conftest import shrunk_upper_arms, wrist_error


@pytest.fixture(scope="module")
def walk(real_walk: np.ndarray) -> np.ndarray:
    """4 s of Bandai's normal walk (80, 22, 3), data convention (floor at the lowest joint)."""
    return real_walk[:80]


def test_p_keeps_the_wrists_of_arms_whose_bones_change_length(real_walk: np.ndarray) -> None:
    """With ``reach_arms`` (the default) P's reference fits the arms to the body's bones: with the elbows slid
    8 cm up the upper arms for four frames, its wrists stay on the motion's; copying the bones' directions as
    they are puts them 3-4 cm off and swings them faster than the motion (issue 62's frame jumps)."""
    moved = shrunk_upper_arms(real_walk[:60])
    assert ProjectionConfig().reach_arms and ProjectionConfig.sampling().reach_arms
    errors = {}
    for on in (True, False):
        prep = prepare_motion(moved, 20.0, replace(ProjectionConfig.sampling(), reach_arms=on))
        ref = qpos_to_joints(resample_qpos(prep.target, 30.0, 20.0, count=len(moved)), prep.model)
        errors[on] = wrist_error(ref[10:35], moved[10:35])
    assert errors[True] < 0.01 < 0.03 < errors[False]


def test_tracks_a_real_walk(walk: np.ndarray) -> None:
    out = project(walk)
    assert out.success and out.selected
    assert out.joints.shape == out.simulated.shape == walk.shape and out.mpjpe.shape == (80,)
    # metres: 48 mm on average over all 203 walk/run clips (experiments/projection_quality.py)
    assert out.mpjpe.mean() < 0.04
    assert np.isnan(out.reference_step)  # recorded only when asked for (one more forward kinematics)


def test_the_reference_step_is_the_walks_retargeted(walk: np.ndarray) -> None:
    """The reference P tracked is the walk retargeted onto the humanoid and shaped: it moves no joint much
    faster than the walk does."""
    out = project(walk, config=ProjectionConfig(record_reference_step=True))
    assert abs(float(out.reference_step) - largest_step(walk)) < 0.005
    # A MuJoCo contact at the sampled instant in 71 % of the frames: with stiff contacts the loaded foot
    # bounces off by a few mm between impacts.
    assert out.contacts.any(axis=1).mean() >= 0.6
    after = physical_metrics(out.simulated, body=HumanoidSurface(body_from_joints(walk)))
    # MuJoCo's soft contacts let the loaded soles sink a little: 1.7 mm here; the 1 mm is a mean
    # over clips (test_walking_and_running_clips_meet_the_targets), and clips spread (p90 1.8 mm).
    assert after["penetrate"] < 2.5


@pytest.mark.slow
def test_walking_and_running_clips_meet_the_targets(mocap_dir) -> None:
    """The issue's all-clips targets on every 8th walking/running clip (26 of 203; the whole set is
    experiments/projection_quality.py). Input measured grounded on the humanoid's surface (the metrics' floor
    convention). Skate: the simulated feet slide more than the captured ones (a shortfall): on these 26
    3.9 -> 6.1 mm (1.54x); all 203 clips are in results/projection_dynamic.md."""
    from experiments.projection_quality import locomotion_clips, measure_clips

    clips = locomotion_clips(mocap_dir)[::8]
    measured = measure_clips(clips)
    ok = [bool(m.result.success) for m in measured]
    mpjpe = [float(m.result.mpjpe.mean()) for m in measured]
    before, after = [m.before for m in measured], [m.after for m in measured]
    mean = lambda rows, key: float(np.mean([r[key] for r in rows]))  # noqa: E731
    print(f"\n{sum(ok)}/{len(ok)} tracked, MPJPE {1000 * np.mean(mpjpe):.1f} mm, penetrate "
          f"{mean(before, 'penetrate'):.2f} -> {mean(after, 'penetrate'):.2f}, skate "
          f"{mean(before, 'skate'):.2f} -> {mean(after, 'skate'):.2f}, phys_err "
          f"{mean(before, 'phys_err'):.2f} -> {mean(after, 'phys_err'):.2f}")
    assert len(clips) >= 25
    assert np.mean(ok) >= 0.95
    assert np.mean(mpjpe) <= 0.060
    assert mean(after, "penetrate") <= 1.0
    assert mean(after, "phys_err") <= mean(before, "phys_err")
    assert mean(after, "skate") <= 1.6 * mean(before, "skate")  # 1.54x measured


def test_deterministic_and_batch_equals_one_by_one(walk: np.ndarray) -> None:
    short = walk[:40]
    one = project(short)
    again = project(short)
    np.testing.assert_array_equal(one.simulated, again.simulated)
    batch = project(np.stack([short, short[::-1].copy()]), config=ProjectionConfig(workers=2))
    np.testing.assert_array_equal(batch.simulated[0], one.simulated)
    np.testing.assert_array_equal(batch.mpjpe[0], one.mpjpe)
    np.testing.assert_array_equal(batch.simulated[1], project(short[::-1].copy()).simulated)


def _before_after(key: str, motion: np.ndarray, projected: np.ndarray, body_of: np.ndarray) -> tuple:
    """A physical metric of a test motion and of its projection, on the humanoid of ``body_of``'s body."""
    surface = HumanoidSurface(body_from_joints(body_of))
    return (physical_metrics(motion.astype(np.float32), body=surface)[key],
            physical_metrics(projected, body=surface)[key])  # fmt: skip


def test_a_floating_walk_comes_down(walk: np.ndarray) -> None:
    lifted = walk + np.array([0.0, 0.1, 0.0])
    out = project(lifted)
    before, after = _before_after("float", lifted, out.simulated, walk)
    print(f"\nfloat {before:.1f} -> {after:.1f} mm")
    # The issue asks for -90 %. Measured 75.5 -> 0.8 mm: the reference, floating for more than a second,
    # is lowered onto the floor (physics/shaping.py); tracked 10 cm up, the body hopped (7.8 mm).
    assert after < 0.1 * before


def test_a_sunk_walk_comes_up(walk: np.ndarray) -> None:
    sunk = walk - np.array([0.0, 0.1, 0.0])
    out = project(sunk)
    assert out.success and out.selected  # the reference is raised out of the floor, so it is tracked
    before, after = _before_after("penetrate", sunk, out.joints, walk)
    print(f"\npenetrate {before:.1f} -> {after:.1f} mm")
    assert after < 0.1 * before  # the issue asks for -90 %


def test_a_dragged_root_skates_less(mocap_dir) -> None:
    """A bow (feet planted) whose whole body is dragged 0.5 m sideways over 4 s: its feet slide in the
    input; the simulated feet hold on to the floor."""
    from physmotion.io.importer import import_clip, load_manifest

    clips = {c.clip: c for c in load_manifest(mocap_dir)}
    bow = import_clip(clips["bandai1_dataset-1_bow_active_001"]).joints[:80].astype(np.float64)
    dragged = bow + np.linspace(0.0, 0.5, len(bow))[:, None, None] * np.array([1.0, 0.0, 0.0])
    out = project(dragged)
    assert out.success
    before, after = _before_after("skate", dragged, out.joints, bow)
    print(f"\nskate {before:.1f} -> {after:.1f} mm")
    # Measured 6.5 -> 3.9 mm (ankle kp 1500; 4.2 mm at 5000). The simulated feet creep a little by
    # themselves (the undragged bow: 0.7 -> 1.1 mm; 2.6 mm at 5000); a drag of 0.2 m: 2.8 -> 2.1 mm.
    assert after < 0.75 * before


def test_follow_drift_moves_the_motion_to_a_body_that_drifted(walk: np.ndarray) -> None:
    """A walk whose root travels 2.5 times as far as its steps carry it (its feet slide, as generated
    motions' do): the body falls behind. Reset onto the motion, it jumps; followed, it walks on. In the
    sampling preset, the one that resets: with the plain projection's 0.2 W residual the followed body
    fell behind by more than its pose allowed and was reset once too. (The tracker's own rules: the
    search's recovery is off.)"""
    root = walk[:, 0, :] - walk[0, 0, :]
    sliding = walk + 1.5 * root[:, None, :] * np.array([1.0, 0.0, 1.0])
    reset = project(sliding, config=ProjectionConfig.sampling(tau=0.3, follow_drift=False, recover=False))
    followed = project(sliding, config=ProjectionConfig.sampling(tau=0.3, recover=False))
    step = {name: np.linalg.norm(np.diff(out.simulated[:, 0], axis=0), axis=-1).max()
            for name, out in (("reset", reset), ("followed", followed))}  # fmt: skip
    print(f"\nlargest pelvis step per frame: reset {step['reset']:.2f} m, followed {step['followed']:.2f} m")
    assert not reset.success and step["reset"] > 0.25  # measured 0.33 m in one frame: a teleport
    assert followed.success and step["followed"] < 0.15  # measured 0.11 m (2.2 m/s)
    assert followed.mpjpe.max() > 0.5  # it was moved: far from the input's absolute positions


def test_a_reset_is_cross_faded_and_its_frames_marked(walk: np.ndarray) -> None:
    """The sliding walk above, reset where it falls behind: the simulation teleports (a jump of a third of
    a metre in one frame), the output does not. Over the 0.25 s before each reset the output is blended
    onto the motion it is put back on; those frames and the reset's are marked as not simulated, and no
    joint moves more from frame to frame there than the input's fastest joint + 2 cm (issue 62's line)."""
    root = walk[:, 0, :] - walk[0, 0, :]
    sliding = walk + 1.5 * root[:, None, :] * np.array([1.0, 0.0, 1.0])
    out = project(sliding, config=ProjectionConfig.sampling(tau=0.3, follow_drift=False, recover=False))
    hard = project(sliding, config=ProjectionConfig.sampling(tau=0.3, follow_drift=False, crossfade=0.0,
                                                             recover=False))  # fmt: skip

    def steps(j: np.ndarray) -> np.ndarray:  # (T - 1,) the fastest joint's move into each frame
        return np.linalg.norm(np.diff(j, axis=0), axis=-1).max(axis=-1)

    marked = np.flatnonzero(out.reset_frames)
    resets = marked[np.r_[np.diff(marked) > 1, True]]  # the last marked frame of each run
    fastest_in = float(steps(sliding).max())
    print(f"\nresets {int(out.resets)} at frames {resets.tolist()}; fastest joint per frame: input {fastest_in:.3f} "
          f"m; into the reset frames, simulated {np.round(steps(out.simulated)[resets - 1], 2).tolist()}, output "
          f"{np.round(steps(out.joints)[resets - 1], 2).tolist()} m")
    assert out.resets >= 1 and np.array_equal(out.simulated, hard.simulated)  # the fade changes the output alone
    assert np.all(steps(hard.joints)[resets - 1] > 0.25)  # each reset a teleport of more than a quarter metre
    # 5 frames (0.25 s at 20 fps) before each reset and the reset's own; the rest is the simulation
    assert len(marked) == 6 * int(out.resets) and not hard.reset_frames[~np.isin(np.arange(80), resets)].any()
    assert np.array_equal(out.joints[~out.reset_frames], out.simulated[~out.reset_frames])
    into = np.unique(np.concatenate([marked - 1, marked]))  # every move into and within the fades
    assert steps(out.joints)[into[into < 79]].max() <= fastest_in + 0.02


def test_a_body_short_of_a_flight_lands_instead_of_being_reset(walk: np.ndarray) -> None:
    """The walk lifted by up to 0.3 m for 0.8 s, as a generated jump higher than the humanoid can push
    off for: the simulated body walks on below the motion, in its pose. Reset (``let_land`` off), it
    is put back up into the air; let land (the sampling preset's default), it stays on the floor."""
    t = np.arange(len(walk)) / 20.0
    lift = np.where((t >= 1.5) & (t <= 2.3), 0.3 * np.sin(np.pi * (t - 1.5) / 0.8), 0.0)
    hover = walk + lift[:, None, None] * np.array([0.0, 1.0, 0.0])
    reset = project(hover, config=ProjectionConfig.sampling(let_land=False, recover=False))
    landed = project(hover, config=ProjectionConfig.sampling(recover=False))
    rise = {name: np.diff(out.simulated[:, 0, 1]).max()
            for name, out in (("reset", reset), ("landed", landed))}  # fmt: skip
    print(f"\nresets {reset.resets} -> {landed.resets}; pelvis rise per frame {rise['reset']:.3f} -> "
          f"{rise['landed']:.3f} m")
    assert reset.resets >= 1 and rise["reset"] > 0.08  # measured 2 resets, 0.12 m up in one frame
    assert landed.resets == 0 and landed.success and rise["landed"] < 0.04  # measured 0.02 m
    assert landed.simulated[:, 0, 1].max() < walk[:, 0, 1].max() + 0.05  # it never left the floor


def test_imitation_selection_keeps_the_input_when_tracking_fails(walk: np.ndarray) -> None:
    jumpy = walk[:40].copy()
    jumpy[20:, :, 0] += 3.0  # teleports 3 m sideways: no body can follow
    out = project(jumpy)
    assert not out.success and not out.selected
    np.testing.assert_array_equal(out.joints, jumpy.astype(np.float32))
    assert out.mpjpe.max() > 0.5


def test_features_are_accepted(walk: np.ndarray) -> None:
    feats, canon = extract_features(walk[:41])
    out = project(feats)
    assert out.simulated.shape == (40, 22, 3) and out.success


@pytest.mark.parametrize(
    "bad, match",
    [(np.full((10, 22, 3), np.nan), "NaN"), (np.zeros((10, 21, 3)), "must be joints"),
     (np.zeros((1, 22, 3)), "at least 2 frames"), (np.full((10, 263), np.inf), "NaN or infinite")],
)  # fmt: skip
def test_bad_input_is_refused(bad: np.ndarray, match: str) -> None:
    with pytest.raises(ShapeError, match=match):
        project(bad)


def _clip(mocap_dir, name: str) -> tuple[np.ndarray, float]:
    from physmotion.io.importer import import_clip, load_manifest

    motion = import_clip({c.clip: c for c in load_manifest(mocap_dir)}[name], floor="frame0")  # P's input
    return motion.joints.astype(np.float64), motion.fps


def _before_dynamic() -> ProjectionConfig:
    """P as it was before the dynamic-motion work: no toe-off flattening, the residual carries the whole
    root wrench (experiments/projection_dynamic.py's "tracker v0.1" row)."""
    from physmotion.physics.shaping import ShapingConfig
    from physmotion.physics.tracking import TrackingConfig

    return ProjectionConfig(tracking=TrackingConfig(feet_balance=False), shaping=ShapingConfig(flatten_toe_off=False))


@pytest.mark.slow
def test_captured_runs_keep_their_airborne_share(mocap_dir) -> None:
    """Every 4th run of the mocap (14 of 53 by caption category): the simulated runners are airborne about
    as often as the captured ones, where the tracker as it was flew in twice as many frames. These 14:
    airborne 12 -> 24 % (the issue allows 10 points: 11.7 here), Float 7.2 -> 11.6 mm. Measured on toes
    that bend (docs/decisions/metrics.md "toes that bend"): the import now stands the captured runners'
    soles lower, so the input reads less airborne and less Float (14 % and 8.7 mm on rigid toes, when the
    gaps were 9.6 points and 2.5 mm) while the simulated output is as it was (24 %, 11.2 mm). Over all 53
    runs, on rigid toes, the issue's Float target (input + 2 mm) missed by 2.2 mm
    (results/projection_dynamic.md). Checked at 12 points and input + 4.5 mm: shortfalls."""
    from experiments.projection_quality import category, measure_clips, summarize
    from physmotion.io.importer import load_manifest

    runs = [c for c in load_manifest(mocap_dir) if category(c.captions) == "run"][::4]
    now, before = summarize(measure_clips(runs)), summarize(measure_clips(runs, _before_dynamic()))
    print(f"\n{len(runs)} runs: airborne {now['airborne_in']:.2f} -> {now['airborne_out']:.2f} (before: "
          f"{before['airborne_out']:.2f}); float {now['float_in']:.1f} -> {now['float_out']:.1f} (before: "
          f"{before['float_out']:.1f}) mm; success {now['success']:.2f}, MPJPE {now['mpjpe_mm']:.0f} mm")
    assert len(runs) >= 13 and now["success"] >= 0.95 and now["mpjpe_mm"] <= 60.0
    assert abs(now["airborne_out"] - now["airborne_in"]) <= 0.12
    assert before["airborne_out"] - before["airborne_in"] > 0.15  # what changed: it flew
    assert now["float_out"] <= now["float_in"] + 4.5 < before["float_out"]
    assert now["penetrate_out"] < now["penetrate_in"]


def _flight_apex(joints: np.ndarray, surface, simulated: np.ndarray, fps: float) -> tuple[float, float]:
    """Pelvis apex (m) of the longest flight of captured ``joints`` (T, 22, 3) (no foot patch within
    AIRBORNE_HEIGHT), and of ``simulated`` within 0.2 s of it."""
    from experiments.projection_quality import AIRBORNE_HEIGHT

    air = surface.foot_heights(joints).min(axis=-1) > AIRBORNE_HEIGHT
    edges = np.flatnonzero(np.diff(np.r_[0, air.astype(np.int8), 0]))
    start, end = max(zip(edges[::2], edges[1::2]), key=lambda se: se[1] - se[0])
    pad = int(0.2 * fps)
    return float(joints[start:end, 0, 1].max()), float(simulated[max(start - pad, 0) : end + pad, 0, 1].max())


def test_captured_jumps_keep_their_flight(mocap_dir) -> None:
    """The three single jumps of the mocap (CMU 02_04 as BVH and as iClone; 01_01's forward jumps): the
    airborne share holds, and the pelvis reaches the apex of the longest flight 6.6 cm short on average
    (6.9, 7.0, 5.7; the tracker as it was: 12.7, 11.4, 10.9; other residual settings:
    docs/decisions/projection.md "residual within 0.1 W on walks and runs"). The issue asks for 3 cm: a
    shortfall."""
    from experiments.projection_quality import measure_projection
    from physmotion.physics.surface import ground_on_surface

    short = []
    for name in ("cmu_02_04", "cmuiclone_02_04", "cmu_01_01"):
        jump, fps = _clip(mocap_dir, name)
        m = measure_projection(jump, fps)
        grounded, body = ground_on_surface(jump)
        apex_in, apex_out = _flight_apex(grounded, HumanoidSurface(body), m.result.simulated, fps)
        short.append(apex_in - apex_out)
        assert m.result.success and m.result.selected
        assert abs(m.airborne_after - m.airborne_before) <= 0.10
    print(f"\napex short by {np.round(100 * np.array(short), 1)} cm")
    assert np.mean(short) <= 0.07 and max(short) <= 0.08


def test_a_generated_jump_keeps_its_flight_with_a_faster_push_off() -> None:
    """The shipped model's plain sample of "a person jumps forward" (seed 0, 6 s; issue 62's example) flies
    23 cm but leaves the floor at 1.5 m/s, too slow for that rise: generation's P as it was kept 9.5 cm
    (measured). With the push-off played faster (``ShapingConfig.push_off``, on in the sampling preset) the
    body jumps as high as the sample, with no reset."""
    from dataclasses import replace

    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.physdiff import on_data_floor
    from physmotion.generate import GenerateConfig, generate
    from physmotion.metrics.actions import flight_height

    sample = generate(["a person jumps forward"], GenerateConfig(seconds=6.0, physics="none", seed=0),
                      model=MotionDiffusion.load()).motions[0].joints  # fmt: skip
    x = on_data_floor(sample)
    config = ProjectionConfig.sampling(recover=False)
    pushed = project(x, config=config)
    as_sampled = project(x, config=replace(config, shaping=replace(config.shaping, push_off=False)))
    kept = [flight_height(r.joints) / flight_height(x) for r in (as_sampled, pushed)]
    print(f"\nflight kept {kept[0]:.2f} as sampled, {kept[1]:.2f} with the push-off")
    assert kept[0] < 0.6 and kept[1] >= 0.8 and pushed.resets == 0
    assert not ProjectionConfig().shaping.push_off  # the plain P, for captured motion, keeps its pace


def _with_right_foot_tilted(monkeypatch: pytest.MonkeyPatch, degrees: float) -> None:
    """P's humanoid built with its right foot bone pitched ``degrees`` more (toe down) than it fits."""
    import physmotion.physics.projection as projection
    from physmotion.skeleton import JOINT_INDEX

    def tilted(joints: np.ndarray, fps: float = 20.0) -> np.ndarray:
        off = body_from_joints(joints, fps)
        v = off[JOINT_INDEX["right_foot"]]
        flat, length = np.linalg.norm(v[[0, 2]]), np.linalg.norm(v)
        p = np.arctan2(-v[1], flat) + np.radians(degrees)
        direction = np.array([v[0] / flat * np.cos(p), -np.sin(p), v[2] / flat * np.cos(p)])
        off[JOINT_INDEX["right_foot"]] = length * direction
        return off

    monkeypatch.setattr(projection, "body_from_joints", tilted)


@pytest.mark.slow
def test_a_take_off_that_falls_short_is_searched_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """The shipped model's "a person jumps forward" (seed 0, 6 s): generation's tracker keeps 0.97 of its
    flight (measured), but on a humanoid whose right foot is pitched 1 degree flatter it keeps 0.48: its
    take-off speed turns on such details. With ``rescue_flight`` the search re-does every take-off whose
    flight the body kept under 0.8 of the reference's, with no outside hand: the tilted body keeps the
    flight (0.99 measured) and nothing is reset; on the fitted body the flights it re-did fly higher than
    the tracker's, the frames before the first are the tracker's, and the search's frames have no hand."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.physdiff import on_data_floor
    from physmotion.generate import GenerateConfig, generate
    from physmotion.metrics.actions import flight_height

    sample = generate(["a person jumps forward"], GenerateConfig(seconds=6.0, physics="none", seed=0),
                      model=MotionDiffusion.load()).motions[0].joints  # fmt: skip
    x = on_data_floor(sample)
    rescuing = ProjectionConfig.sampling(rescue_flight=0.8)
    tracked, rescued = project(x, config=ProjectionConfig.sampling()), project(x, config=rescuing)
    frames = np.flatnonzero(rescued.recovered_frames)
    stretches = np.split(frames, np.flatnonzero(np.diff(frames) > 1) + 1)
    higher = [tuple(flight_height(out.joints[f].astype(np.float64)) for out in (tracked, rescued))
              for f in stretches]  # fmt: skip
    print(f"\nre-done stretches {[(int(f[0]), int(f[-1])) for f in stretches]}, flight tracker -> search "
          f"{np.round(higher, 3)}")
    assert tracked.recovered == 0 and rescued.recovered >= 1 and rescued.resets == 0
    assert all(b > a for a, b in higher)
    assert not rescued.residual[frames].any() and not rescued.at_cap[frames].any()
    before = slice(0, max(0, frames[0] - 1))
    np.testing.assert_array_equal(rescued.joints[before], tracked.joints[before])
    _with_right_foot_tilted(monkeypatch, -1.0)
    kept = [flight_height(project(x, config=c).joints.astype(np.float64)) / flight_height(x)
            for c in (ProjectionConfig.sampling(), rescuing)]  # fmt: skip
    print(f"right foot 1 degree flatter: flight kept {kept[0]:.2f} by the tracker, {kept[1]:.2f} rescued")
    assert kept[0] < 0.6 and kept[1] >= 0.8


def test_a_first_frame_off_the_motions_path_is_mended_before_p_starts(walk: np.ndarray) -> None:
    """The walk with its first frame's right wrist 7 cm off (a denoiser's boundary artefact, as measured in
    PhysDiff's last x0: 6-9 cm): P starts the body where the motion goes, so the output moves into frame 1
    as the motion moves on from it; without the mend the output carries the jump. A walk whose first
    frame is on its path is unchanged."""
    from physmotion.physics.projection import mend_first_frame
    from physmotion.skeleton import JOINT_INDEX

    def step(j: np.ndarray, f: int) -> float:  # the fastest joint's move from frame f to f + 1, metres
        return float(np.linalg.norm(j[f + 1] - j[f], axis=-1).max())

    off = walk.copy()
    off[0, JOINT_INDEX["right_wrist"]] += np.array([0.05, -0.05, 0.0])
    mended = project(off, config=ProjectionConfig.sampling())
    carried = project(off, config=ProjectionConfig.sampling(mend_first_frame=False))
    print(f"\nfirst step: input {step(off, 0):.3f} m (next {step(off, 1):.3f}), output {step(carried.joints, 0):.3f} "
          f"unmended, {step(mended.joints, 0):.3f} mended")
    assert step(carried.joints, 0) > step(off, 1) + 0.02  # measured 0.040 against 0.013: the jump goes through P
    assert step(mended.joints, 0) <= step(off, 1) + 0.005
    assert mend_first_frame(walk, 0.02) is walk  # on the path: untouched


def test_the_fallback_leaves_what_the_tracker_follows(walk: np.ndarray) -> None:
    """A walk the tracker follows with no reset and no flight to keep: the fallback changes nothing."""
    plain = project(walk, config=ProjectionConfig.sampling())
    with_fallback = project(walk, config=ProjectionConfig.sampling(fallback=True))
    assert plain.resets == 0 and not plain.searched and not with_fallback.searched
    np.testing.assert_array_equal(with_fallback.joints, plain.joints)


@pytest.mark.slow
def test_the_search_takes_over_a_jump_the_tracker_flattens(mocap_dir) -> None:
    """CMU 01_01's first forward jump (2.5 s): generation's tracker with the push-off as captured keeps 0.57
    of its flight (both feet off the floor, 18.9 cm -> 10.8 cm measured); as its fallback the search keeps
    0.97 (18.3 cm) with no outside hand and no reset. With the push-off played faster (the sampling preset's
    default) the tracker itself keeps 0.95 (measured) and the fallback has nothing to take over."""
    from dataclasses import replace

    from physmotion.metrics.actions import flight_height

    jump, fps = _clip(mocap_dir, "cmu_01_01")
    jump = jump[: int(2.5 * fps)]
    preset = ProjectionConfig.sampling()
    as_captured = replace(preset, shaping=replace(preset.shaping, push_off=False))
    tracked = project(jump, fps=fps, config=as_captured)
    searched = project(jump, fps=fps, config=replace(as_captured, fallback=True))
    pushed = project(jump, fps=fps, config=replace(preset, fallback=True))
    outs = (jump, tracked.joints, searched.joints, pushed.joints)
    flight = [flight_height(j.astype(np.float64)) for j in outs]
    print(f"\nflight {flight[0]:.3f} m: tracker {flight[1]:.3f}, fallback {flight[2]:.3f}, with the push-off "
          f"{flight[3]:.3f}; resets {tracked.resets} / {searched.resets} / {pushed.resets}")
    assert flight[3] >= 0.8 * flight[0] and not pushed.searched and pushed.resets == 0
    assert flight[1] < 0.8 * flight[0] and not tracked.searched  # what triggers the fallback
    assert searched.searched and searched.success and searched.resets == 0
    assert flight[2] >= 0.9 * flight[0]
    assert not searched.residual.any() and not searched.at_cap.any() and not searched.over_limit.any()


@pytest.mark.slow
def test_the_search_carries_a_falling_body_instead_of_a_reset() -> None:
    """The shipped model's plain sample of a hop (seed 2, 4 s): generation's tracker falls in it and puts the
    body back twice (measured); with ``recover`` the search carries the body over the fall (about 1 s) with
    no outside hand, and nothing is reset. Where it carried, no residual was applied; elsewhere the output is
    the tracker's."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.physdiff import on_data_floor
    from physmotion.generate import GenerateConfig, generate

    sample = generate(["a child hops around happily"], GenerateConfig(seconds=4.0, physics="none", seed=2),
                      model=MotionDiffusion.load()).motions[0].joints  # fmt: skip
    x = on_data_floor(sample)
    reset = project(x, config=ProjectionConfig.sampling(recover=False))
    carried = project(x, config=ProjectionConfig.sampling())
    frames = np.flatnonzero(carried.recovered_frames)
    print(f"\nresets {reset.resets} -> {carried.resets}; carried {carried.recovered} time(s), frames {frames}")
    assert reset.resets >= 1 and reset.recovered == 0 and not reset.recovered_frames.any()
    assert carried.resets == 0 and carried.recovered >= 1 and carried.success
    # 0.5 s either side of the fall, at 20 fps: 20-30 frames on the CI machine; on an AMD EPYC the search
    # carries three stretches that meet, 34 frames (measured before and after the push-off): not the motion
    assert 10 <= len(frames) <= 40
    assert not carried.residual[frames].any() and not carried.at_cap[frames].any()
    assert not carried.reset_frames.any()
    before = slice(0, max(0, frames[0] - 1))  # the tracker's frames before the stretch are untouched
    np.testing.assert_array_equal(carried.joints[before], reset.joints[before])


def test_where_the_search_falls_it_tries_once_more_from_further_back(monkeypatch: pytest.MonkeyPatch) -> None:
    """``ProjectionConfig.recover``: a search that falls from ``recover_back`` before the failing step is run
    again from ``recover_retry_back`` before it (more time to steer the body), and only if that falls too is
    the step left to a reset; with ``recover_retry_back`` 0 there is no second try."""
    from types import SimpleNamespace

    import physmotion.physics.projection as projection

    starts: list[int] = []

    class _FallsFirst:  # a search that falls when started 0.5 s before the step, not 1 s before
        def __init__(self, *args) -> None:
            pass

        def run(self, ref, start):
            k = 40
            starts.append(k + 15 - len(ref.qpos) + 1)  # stop = k + 15 + 1 (0.5 s ahead at 30 Hz)
            m = len(ref.qpos)
            roll = SimpleNamespace(failed_at=2 if len(starts) == 1 else None, qpos=np.zeros((m, 3)),
                                   mpjpe=np.zeros(m), contacts=np.zeros((m, 4), dtype=bool))  # fmt: skip
            return roll, SimpleNamespace(qvel=np.zeros((m, 3)))

    monkeypatch.setattr(projection, "SearchController", _FallsFirst)
    ref = SimpleNamespace(qpos=np.zeros((100, 3)), window=lambda a, b: SimpleNamespace(qpos=np.zeros((b - a, 3))))
    states = np.zeros((41, 6))
    got = projection._recovery(None, ProjectionConfig.sampling(recover=True))(ref, states, 40, 0)
    assert starts == [25, 10] and got.start == 10 and len(got.qpos) == 40 + 15 - 10 + 1
    starts.clear()
    once = projection._recovery(None, ProjectionConfig.sampling(recover=True, recover_retry_back=0.0))
    assert once(ref, states, 40, 0) is None and starts == [25]
    starts.clear()  # an earlier stretch bounds both tries at the same start: the same search is not run twice
    assert projection._recovery(None, ProjectionConfig.sampling(recover=True))(ref, states, 40, 30) is None
    assert starts == [30]


def test_recover_is_for_the_tracker_with_resets() -> None:
    with pytest.raises(ShapeError, match="recover"):
        ProjectionConfig(controller="search", reset_on_fail=True, recover=True)
    with pytest.raises(ShapeError, match="recover"):
        ProjectionConfig(recover=True)  # no reset to replace
    with pytest.raises(ShapeError, match="recover_back"):
        ProjectionConfig.sampling(recover_back=-1.0)
    with pytest.raises(ShapeError, match="recover_retry_back"):
        ProjectionConfig.sampling(recover_retry_back=6.0)


def test_the_flight_rescue_needs_recover() -> None:
    with pytest.raises(ShapeError, match="rescue_flight"):
        ProjectionConfig.sampling(rescue_flight=1.5)
    with pytest.raises(ShapeError, match="needs recover"):
        ProjectionConfig.sampling(recover=False, rescue_flight=0.8)
    assert ProjectionConfig.sampling(rescue_flight=0.8).with_controller("search").rescue_flight == 0.0


def test_the_fallback_is_for_the_tracker() -> None:
    with pytest.raises(ShapeError, match="fallback"):
        ProjectionConfig(controller="search", fallback=True)
    with pytest.raises(ShapeError, match="fallback_flight"):
        ProjectionConfig(fallback_flight=1.5)


def test_a_non_grounded_motion_is_rejected_not_tracked_into_the_floor(mocap_dir) -> None:
    """A bow held 0.3 m up for 2 s (standing on something we do not simulate): the humanoid can only
    imitate it on the floor (MPJPE about 0.32 m, under Morph's 0.5 m), so selection must reject it for
    not being grounded; the bow itself is kept."""
    from scipy.ndimage import uniform_filter1d

    bow, _ = _clip(mocap_dir, "bandai1_dataset-1_bow_active_001")
    bow = bow[:100]
    up = np.zeros(len(bow))
    up[30:70] = 0.3
    raised = bow + uniform_filter1d(up, 5)[:, None, None] * np.array([0.0, 1.0, 0.0])
    out = project(raised)
    assert not out.grounded and not out.selected
    assert out.mpjpe.max() < 0.5  # the MPJPE alone would have kept it
    np.testing.assert_array_equal(out.joints, raised.astype(np.float32))
    plain = project(bow)
    assert plain.grounded and plain.selected


def test_a_run_is_deterministic_and_batch_equals_one_by_one(mocap_dir, walk: np.ndarray) -> None:
    """The feet-balance fit, the toe-off flattening and iterative learning control are deterministic too;
    a batch mixing a run and a walk gives what each gives alone."""
    run, fps = _clip(mocap_dir, "bandai2_dataset-2_run_feminine_001")
    assert fps == 20.0
    run = run[:60]
    batch = project(np.stack([run, walk[:60]]))
    alone = project(run)
    again = project(run)
    np.testing.assert_array_equal(alone.simulated, again.simulated)
    np.testing.assert_array_equal(batch.simulated[0], alone.simulated)
    ilc = ProjectionConfig(ilc_passes=1)  # iterative learning control as well
    np.testing.assert_array_equal(project(run, config=ilc).simulated, project(run, config=ilc).simulated)
    np.testing.assert_array_equal(batch.residual[0], alone.residual)
    np.testing.assert_array_equal(batch.simulated[1], project(walk[:60]).simulated)


@pytest.mark.slow
def test_ilc_brings_runs_closer_to_the_input(mocap_dir) -> None:
    """Iterative learning control (``ilc_passes=2``) on every 6th captured run: the root's error fed
    forward brings the runners closer to the input and out of the air they added, and the kept pass is
    never worse than the first simulation. Measured on these 9 runs: MPJPE 47.4 -> 33.1 mm, Float 20.5 ->
    15.5 mm (input 12.8), a later pass kept on 7; over all 53 runs (results/projection_dynamic.md) Float
    15.0 -> 12.5 mm meets the issue's input + 2 mm, and MPJPE goes 50.2 -> 42.6 mm."""
    from dataclasses import replace

    from experiments.projection_quality import category, measure_clips, summarize
    from physmotion.io.importer import load_manifest

    runs = [c for c in load_manifest(mocap_dir) if category(c.captions) == "run"][::6]
    plain_each = measure_clips(runs)
    ilc_each = measure_clips(runs, replace(ProjectionConfig(), ilc_passes=2))
    plain, ilc = summarize(plain_each), summarize(ilc_each)
    print(f"\n{len(runs)} runs: MPJPE {plain['mpjpe_mm']:.1f} -> {ilc['mpjpe_mm']:.1f} mm, Float "
          f"{plain['float_out']:.1f} -> {ilc['float_out']:.1f} mm (input {plain['float_in']:.1f}), Skate "
          f"{plain['skate_out']:.1f} -> {ilc['skate_out']:.1f} mm, passes kept "
          f"{[int(m.result.ilc_pass) for m in ilc_each]}")
    assert ilc["success"] == 1.0
    for p, i in zip(plain_each, ilc_each):  # the first pass is the plain projection: kept unless beaten
        assert i.result.mpjpe.mean() <= p.result.mpjpe.mean() + 1e-9
        assert (int(i.result.ilc_pass) == 0) == np.array_equal(i.result.simulated, p.result.simulated)
    assert ilc["mpjpe_mm"] <= 0.85 * plain["mpjpe_mm"]
    assert ilc["float_out"] < plain["float_out"] - 1.0
    assert sum(int(m.result.ilc_pass) > 0 for m in ilc_each) >= len(runs) // 2


def test_ilc_settings_are_checked() -> None:
    with pytest.raises(ShapeError, match="ilc_passes"):
        ProjectionConfig(ilc_passes=-1)
    with pytest.raises(ShapeError, match="ilc_gain"):
        ProjectionConfig(ilc_gain=0.0)
    with pytest.raises(ShapeError, match="does not reset the body where it falls"):
        ProjectionConfig.sampling(ilc_passes=1)


def test_fine_step_halves_the_step_and_keeps_the_residual_rate() -> None:
    for config in (ProjectionConfig(ilc_passes=2), ProjectionConfig.sampling()):
        fine = config.at_fine_step()
        assert fine.humanoid.sim_dt == pytest.approx(config.humanoid.sim_dt / 2)
        rate = config.humanoid.sim_dt * config.humanoid.residual_every
        assert fine.humanoid.sim_dt * fine.humanoid.residual_every == pytest.approx(rate)
        assert replace(fine, humanoid=config.humanoid) == config  # nothing else changes


@pytest.mark.slow
def test_fine_step_lands_runs_nearer_the_input(mocap_dir) -> None:
    """``ProjectionConfig().at_fine_step()`` (1/720 s) on every 6th captured run, against the default (1/360 s):
    the runners float less, fly about as often as the captured ones and track closer. Measured on these 9
    runs: MPJPE 47.4 -> 32.7 mm, Float 20.5 -> 12.2 mm (input 12.8), airborne 32 -> 23 % (input 22 %); Skate
    8.3 -> 8.9 mm (input 4.4) is not helped. Over all 53 runs: results/projection_dynamic.md."""
    from experiments.projection_quality import category, measure_clips, summarize
    from physmotion.io.importer import load_manifest

    runs = [c for c in load_manifest(mocap_dir) if category(c.captions) == "run"][::6]
    plain = summarize(measure_clips(runs))
    fine = summarize(measure_clips(runs, ProjectionConfig().at_fine_step()))
    print(f"\n{len(runs)} runs: MPJPE {plain['mpjpe_mm']:.1f} -> {fine['mpjpe_mm']:.1f} mm, Float "
          f"{plain['float_out']:.1f} -> {fine['float_out']:.1f} mm (input {plain['float_in']:.1f}), Skate "
          f"{plain['skate_out']:.2f} -> {fine['skate_out']:.2f} mm (input {plain['skate_in']:.2f}), airborne "
          f"{plain['airborne_out']:.2f} -> {fine['airborne_out']:.2f} (input {plain['airborne_in']:.2f})")
    assert fine["success"] == 1.0
    assert fine["float_out"] < plain["float_out"] - 2.0
    assert fine["float_out"] <= fine["float_in"] + 2.0
    assert fine["mpjpe_mm"] < plain["mpjpe_mm"]
    assert abs(fine["airborne_out"] - fine["airborne_in"]) <= 0.05 < plain["airborne_out"] - plain["airborne_in"]
