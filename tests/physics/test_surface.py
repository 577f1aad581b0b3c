"""The humanoid's collision geometry as a body surface."""

from __future__ import annotations

import numpy as np
import pytest

from physmotion.errors import ShapeError
from physmotion.metrics.physical import physical_metrics
from physmotion.physics.humanoid import body_from_joints
from physmotion.physics.projection import project
from physmotion.physics.surface import HumanoidSurface, ground_on_surface


def test_heights_follow_the_motion_given_not_a_freed_one(real_walk: np.ndarray) -> None:
    """Each call answers for its own array, even when the previous one was a freed temporary whose
    memory (and id) the next array may reuse. A motion and its floor moved up alike move its heights alike
    (the floor bends the toes it meets)."""
    walk = real_walk[:20]
    surface = HumanoidSurface(body_from_joints(walk))
    low = surface.lowest_height(walk.copy())
    for step in (0.1, 0.2, 0.3):  # a run of temporaries of one shape, as a benchmark loop makes them
        moved = walk.astype(np.float32).astype(np.float64) + np.array([0.0, step, 0.0])
        np.testing.assert_allclose(surface.lowest_height(moved, floor=step), low + step, atol=1e-6)
    feet = surface.foot_heights(walk.copy())
    assert feet.shape == (20, 4) and np.all(feet >= low[:, None] - 1e-9)


def test_per_motion_bodies_pose_each_motion_on_its_own(real_walk: np.ndarray) -> None:
    """A list of bodies (None: estimate from the joints) answers as each body alone would."""
    a, b = real_walk[:20], real_walk[40:60]
    body_a = body_from_joints(a)
    batch = np.stack([a, b])
    low = HumanoidSurface([body_a, None]).lowest_height(batch)
    np.testing.assert_allclose(low[0], HumanoidSurface(body_a).lowest_height(a), atol=1e-9)
    np.testing.assert_allclose(low[1], HumanoidSurface().lowest_height(b), atol=1e-9)
    with pytest.raises(ShapeError, match="2 bodies given for 1 motions"):
        HumanoidSurface([body_a, None]).lowest_height(a)
    with pytest.raises(ShapeError, match="offsets must be"):
        HumanoidSurface(np.zeros((22, 2)))


def test_on_the_body_p_simulated_the_surface_agrees_with_mujoco(real_walk: np.ndarray) -> None:
    """``ProjectedMotion.body`` is the body P built, and where MuJoCo had a foot on the floor the surface
    posed with it on the simulated joints puts the lowest point near the floor: 1.8 mm median, 3.1 mm
    mean here. Not exactly on it: loaded soles sink a little into MuJoCo's soft floor, and joints do not
    fix a foot's roll, so the re-posed foot can differ from the simulated one (up to 18 mm in one frame)."""
    walk = real_walk[:80]
    out = project(walk)
    np.testing.assert_allclose(out.body, body_from_joints(walk))
    low = HumanoidSurface(out.body).lowest_height(out.simulated.astype(np.float64))
    contact = out.contacts.any(axis=1)
    assert contact.mean() > 0.5
    off = np.abs(low[contact])
    assert np.median(off) < 0.0025 and off.mean() < 0.004, 1000 * off


def test_grounding_puts_a_captured_walk_on_the_floor(real_walk: np.ndarray) -> None:
    """The metrics' floor convention: the best constant shift. A captured walk in the data convention
    (lowest joint at 0) sinks its soles ~2 cm; grounded, it barely penetrates and its Phys-Err is
    no higher than with its lowest surface point over the clip on the floor (where a heel box dipping its
    corner at a heel strike leaves the stance foot floating; on this walk, with the toes bending at the
    push-off, the two shifts tie)."""
    grounded, body = ground_on_surface(real_walk)
    surface = HumanoidSurface(body)
    assert grounded.dtype == real_walk.dtype and np.allclose(grounded[..., [0, 2]], real_walk[..., [0, 2]])
    lowest = real_walk - [0, surface.lowest_height(real_walk.astype(np.float64)).min(), 0]
    as_data, on_lowest, best = (physical_metrics(j, body=surface) for j in (real_walk, lowest, grounded))
    assert as_data["penetrate"] > 10 and best["penetrate"] < 2.0
    assert best["phys_err"] <= on_lowest["phys_err"] and best["phys_err"] < as_data["phys_err"]
    again, _ = ground_on_surface(real_walk, body)
    np.testing.assert_array_equal(again, grounded)


def test_toes_bend_where_the_floor_meets_them(mocap_dir) -> None:
    """A captured CMU walk, imported: at each push-off the toe box, rigid with the foot as retargeting
    leaves it, points its tip 1-3 cm into the floor while the toe joint stands over it. Bent by the floor,
    no toe box is more than 1 cm under it; a toe that clears the floor keeps its pose (the bend only
    ever raises it), and a toe bent as far as its hinge allows is the highest of all."""
    from physmotion.io import import_clip, load_manifest
    from physmotion.physics.humanoid import HumanoidConfig, build_model
    from physmotion.physics.retarget import joints_to_qpos
    from physmotion.physics.surface import lowest_of, pose_frames, toe_lowest

    clips = {c.clip: c for c in load_manifest(mocap_dir)}
    walk = import_clip(clips["cmuiclone_02_01"]).joints.astype(np.float64)
    body = body_from_joints(walk)
    model = build_model(body)
    xpos, gpos, gmat = pose_frames(model, joints_to_qpos(walk, model))
    toes = np.array([model.geom(f"{side}_foot").id for side in ("left", "right")])
    rigid = lowest_of(model, gpos, gmat, toes)  # (T, 2)
    assert rigid.min() < -0.02 and (rigid < -0.01).sum() >= 6
    surface = HumanoidSurface(body)
    feet = surface.foot_heights(walk)[:, [1, 3]]  # the toe patches, floor at 0
    assert feet.min() > -0.01
    clear = rigid >= 0
    np.testing.assert_array_equal(feet[clear], rigid[clear])
    assert np.all(feet >= rigid - 1e-9)
    pressed = surface.foot_heights(walk, floor=np.inf)[:, [1, 3]]
    highest = np.stack([toe_lowest(model, xpos, gmat, g, HumanoidConfig()) for g in toes], axis=-1)
    np.testing.assert_array_equal(pressed, highest)
    assert np.all(highest >= feet - 1e-9)
    np.testing.assert_array_equal(surface.foot_heights(walk, floor=-np.inf)[:, [1, 3]], rigid)
    assert np.all(surface.lowest_height(walk) <= feet.min(axis=-1))
