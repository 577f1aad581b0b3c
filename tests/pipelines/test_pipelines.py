"""Each generation method as its own pipeline, with the shipped default model: what a call returns, and
that nothing of it is left behind on the pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.samplers import SamplerConfig
from physmotion.errors import ShapeError
from physmotion.generate import GenerateConfig, pipeline_for
from physmotion.motion import Motion
from physmotion.pipelines.morph import MorphPipeline
from physmotion.pipelines.physdiff import PhysDiffPipeline, PostProjectionPipeline
from physmotion.pipelines.plain import FloorPipeline, PlainPipeline

PROMPTS = ["a person walks forward", "a person jumps", "a person waves the right hand"]
LENGTHS = [48, 40, 48]  # mixed, so that P's batches by length must be put back in the prompts' order
FEW = SamplerConfig(steps=6)


@pytest.fixture(scope="module")
def model() -> MotionDiffusion:
    return MotionDiffusion.load()


def _no_state_left(pipeline: object) -> None:
    assert not [k for k in vars(pipeline) if k.startswith("last")]


def test_pipeline_for_picks_one_class_per_method(model: MotionDiffusion) -> None:
    expect = {"none": PlainPipeline, "none+floor": FloorPipeline, "post:2": PostProjectionPipeline,
              "physdiff:end:2,space:1": PhysDiffPipeline, "morph": MorphPipeline}  # fmt: skip
    for spelling, cls in expect.items():
        pipeline = pipeline_for(GenerateConfig(physics=spelling, sampler=FEW), model)
        assert (
            type(pipeline) is cls and pipeline.name == spelling and pipeline.settings()["physics"] == spelling
        )


def test_physdiff_returns_its_projections_in_the_prompts_order(model: MotionDiffusion) -> None:
    pipeline = PhysDiffPipeline(model, FEW, schedule="end:2,space:1")
    res = pipeline(PROMPTS, LENGTHS, seed=1)
    assert res.projections.calls == 2 and len(res.projections.selected) == 2 * len(PROMPTS)
    assert [len(m.joints) for m in res.motions] == LENGTHS  # the last projection is the output
    assert all(m.humanoid is not None and m.residual.shape == (len(m.joints), 2) for m in res.motions)
    assert res.resets == [m.resets for m in res.motions]
    # every call's resets are the motion's: a fall in the first call is not forgotten by the second
    assert res.resets == [res.projections.resets[i] + res.projections.resets[i + len(PROMPTS)]
                          for i in range(len(PROMPTS))]  # fmt: skip
    assert res.settings["pipeline"] == "PhysDiffPipeline" and res.settings["projection"]["reset_on_fail"]
    _no_state_left(pipeline)
    again = pipeline(PROMPTS, LENGTHS, seed=1)  # a second call starts from nothing and is deterministic
    assert again.projections.calls == 2
    assert all(np.array_equal(a.joints, b.joints) for a, b in zip(res.motions, again.motions))


def test_fly_last_projects_a_flying_motion_at_the_last_step_only(
    model: MotionDiffusion, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With ``fly:last``, a motion whose denoised x0 flies when the first P comes is left to the last one,
    which projects every motion; each motion's resets are the sum over the calls that projected it."""
    from physmotion.diffusion.physdiff import FeatureProjector
    from physmotion.metrics.actions import flight_height
    from physmotion.metrics.dynamics import MIN_FLIGHT

    prompts = ["someone leaps high into the air", "a person walks forward",
               "a person does three small jumps in a row"]  # fmt: skip
    seen: list[list[bool]] = []
    pipeline = PhysDiffPipeline(model, FEW, schedule="end:2,space:1,fly:last")
    joints = FeatureProjector.joints

    def spy(self, x0, lengths):  # what the first P sees: which motions fly
        out = joints(self, x0, lengths)
        seen.append([flight_height(j) >= MIN_FLIGHT for j in out])
        return out

    monkeypatch.setattr(FeatureProjector, "joints", spy)
    res = pipeline(prompts, [80, 80, 80], seed=0)
    monkeypatch.undo()
    flying = seen[0]
    assert any(flying) and not all(flying)  # the set has both kinds at the first P (seed 0, shipped model)
    log = res.projections
    assert log.calls == 2 and log.motions == [i for i, f in enumerate(flying) if not f] + [0, 1, 2]
    assert res.resets == log.resets_per_motion(3) == [m.resets for m in res.motions]
    assert all(m.humanoid is not None for m in res.motions)  # the last call's simulation is every output
    plain = PhysDiffPipeline(model, FEW, schedule="end:2,space:1")(prompts, [80, 80, 80], seed=0)
    assert plain.projections.motions == [0, 1, 2, 0, 1, 2]
    walk = flying.index(False)  # a motion projected twice either way is the same motion
    assert np.array_equal(res.motions[walk].joints, plain.motions[walk].joints)


def test_post_projects_k_times_after_sampling(model: MotionDiffusion) -> None:
    steps: list[tuple[int, int]] = []
    post = PostProjectionPipeline(model, FEW, projections=2)
    res = post(PROMPTS[:2], LENGTHS[:2], on_step=lambda i, n: steps.append((i, n)))
    assert res.projections.calls == 2 and steps[-1] == (FEW.steps + 2, FEW.steps + 2)
    assert [len(m.joints) for m in res.motions] == LENGTHS[:2]
    assert all(len(f) == n for f, n in zip(res.features, LENGTHS[:2]))


def test_morph_marks_each_kept_input_on_its_own_motion(model: MotionDiffusion) -> None:
    res = MorphPipeline(model, FEW)(PROMPTS, LENGTHS, seed=2)
    assert len(res.imitation_failed) == len(PROMPTS) and res.projections.calls == 1
    for m, failed, n in zip(res.motions, res.imitation_failed, LENGTHS):
        assert len(m.joints) == n
        assert (m.humanoid is None) == failed and (m.residual is None) == failed


def test_plain_and_floor_differ_by_a_height_only(model: MotionDiffusion) -> None:
    plain = PlainPipeline(model, FEW)(PROMPTS[:2], LENGTHS[:2], seed=3)
    floor = FloorPipeline(model, FEW)(PROMPTS[:2], LENGTHS[:2], seed=3)
    assert plain.projections.calls == 0 and all(
        m.humanoid is None and m.resets is None for m in plain.motions
    )
    for a, b in zip(plain.motions, floor.motions):
        shift = b.joints - a.joints
        assert b.humanoid is not None and np.allclose(shift[..., [0, 2]], 0) and np.ptp(shift[..., 1]) < 1e-5


def test_refine_pipeline_keeps_every_licence_tag(model: MotionDiffusion) -> None:
    from physmotion.diffusion.refine import RefineConfig
    from physmotion.pipelines.refine import RefinePipeline

    walk = PlainPipeline(model, FEW)(PROMPTS[:1], [60], seed=4).motions[0]
    given = Motion(joints=walk.joints, fps=walk.fps, texts=["a walk"], licence_tag="SA", source="test")
    res = RefinePipeline(model, RefineConfig(strength=0.1, steps=20))(given)
    assert res.motion.licence_tag == "NC,SA" and res.motion.joints.shape == walk.joints.shape
    assert res.settings["refine"]["strength"] == 0.1
    with pytest.raises(ShapeError, match="frames at 20 fps"):  # refused before any work
        RefinePipeline(model).check(Motion(joints=walk.joints[:10], fps=walk.fps))
