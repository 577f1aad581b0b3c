"""Generation end to end with a (tiny) trained model: outputs, determinism, physics modes, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physmotion.diffusion.samplers import SamplerConfig
from physmotion.errors import PhysmotionError
from physmotion.generate import GenerateConfig, generate, slug, write_outputs
from physmotion.motion import Motion
from physmotion.physics.projection import ProjectionConfig
from tests.test_cli import run


def _cfg(**kw) -> GenerateConfig:
    """A short request; P resets at once where the tiny model's motions fall (at nearly every step), as the
    search's recovery would try twice at each fall: that is tested on the shipped model's hop below."""
    no_recover = ProjectionConfig.sampling(recover=False)
    return GenerateConfig(**{"seconds": 2.4, "physics": "none", "sampler": SamplerConfig(steps=6),
                             "projection": no_recover} | kw)  # fmt: skip


def test_none_gives_num_motions_per_text_deterministically(tiny_model) -> None:
    a = generate(["a person walks forward", "a person waves"], _cfg(num=2, seed=4), tiny_model)
    b = generate(["a person walks forward", "a person waves"], _cfg(num=2, seed=4), tiny_model)
    assert [m.texts[0] for m in a.motions] == ["a person walks forward"] * 2 + ["a person waves"] * 2
    assert all(m.joints.shape == (48, 22, 3) and m.fps == 20 for m in a.motions)
    assert all(np.array_equal(x.joints, y.joints) for x, y in zip(a.motions, b.motions))
    assert not np.array_equal(a.motions[0].joints, a.motions[1].joints)  # two samples differ
    assert a.motions[0].licence_tag == "NC" and a.projections.calls == 0


def test_physdiff_and_post_call_the_projection(tiny_model) -> None:
    phys = generate(["a person walks"], _cfg(physics="physdiff:end:2,space:1"), tiny_model)
    assert phys.projections.calls == 2
    post = generate(["a person walks"], _cfg(physics="post:2"), tiny_model)
    assert post.projections.calls == 2 and len(post.projections.selected) == 2
    # The output is P's simulation: each motion comes with the humanoid body it was simulated with, the
    # surface its physical metrics are measured on; the last step is projected, so physdiff's is too.
    for out in (phys, post):
        assert len(out.bodies) == 1 and out.bodies[0].shape == (22, 3) and np.all(np.isfinite(out.bodies[0]))
    assert not np.array_equal(phys.bodies[0], post.bodies[0])  # bodies fitted to different motions
    # with this untrained model the humanoid falls, so imitation selection keeps the input: same as none
    none = generate(["a person walks"], _cfg(), tiny_model)
    assert none.bodies == [None]
    unprojected_end = generate(["a person walks"], _cfg(physics="physdiff:start:1,end:0"),
                               tiny_model)
    assert unprojected_end.bodies == [None]  # its last step was not projected: not P's output
    if not any(post.projections.selected):
        assert np.allclose(post.motions[0].joints, none.motions[0].joints)


def test_outputs_are_written(tiny_model, tmp_path: Path) -> None:
    cfg = _cfg(num=2)
    result = generate(["A person walks, then waves!"], cfg, tiny_model)
    paths = write_outputs(result, tmp_path / "out", cfg)
    names = sorted(p.name for p in paths)
    assert names == [f"a_person_walks_then_waves_s0_{k}.{ext}" for k in (0, 1) for ext in ("bvh", "gif", "npz")]
    back = Motion.load(tmp_path / "out" / "a_person_walks_then_waves_s0_0.npz")
    assert np.allclose(back.joints, result.motions[0].joints) and back.texts == ["A person walks, then waves!"]
    from PIL import Image

    assert Image.open(tmp_path / "out" / "a_person_walks_then_waves_s0_0.gif").n_frames == 48
    (summary,) = json.loads((tmp_path / "out" / "generate.json").read_text())["runs"]
    assert summary["licence_tag"] == "NC" and len(summary["files"]) == 6
    assert all(m["resets"] is None and m["reset_frames"] is None for m in summary["motions"])  # no P, no record


def test_resets_and_their_frames_are_one_count_everywhere(tiny_model, tmp_path: Path) -> None:
    """PhysDiff's every call of P counts: the per-motion resets in the files and generate.json add up to
    the run's total, each motion lists its frames that were not simulated, and the summary line says the
    same numbers."""
    from physmotion.generate import physics_summary

    cfg = _cfg(physics="physdiff:end:2,space:1", num=2)
    result = generate(["a person runs fast and jumps"], cfg, tiny_model)
    write_outputs(result, tmp_path / "out", cfg, preview=False)
    (run,) = json.loads((tmp_path / "out" / "generate.json").read_text())["runs"]
    per_motion = [m["resets"] for m in run["motions"]]
    assert sum(per_motion) == run["projections"]["resets_total"] == sum(result.projections.resets)
    for entry, motion in zip(run["motions"], result.motions):
        assert entry["resets"] == motion.resets
        assert entry["reset_frames"] == np.flatnonzero(motion.reset_frames).tolist()
        assert bool(entry["reset_frames"]) == (entry["resets"] > 0)
    print(f"\nresets per motion {per_motion}")
    assert run["projections"]["resets_total"] > 0  # the tiny model's runs fall: the count is exercised
    assert f"{run['projections']['resets_total']} time(s) in all" in physics_summary(result)


def test_the_search_fallback_is_chosen_per_run(tmp_path: Path) -> None:
    """On or off per run; the search controller has none (it searches every motion), and asking for both
    is one line before any work."""
    on = GenerateConfig().with_search_fallback(True)
    assert on.projection.fallback and not on.with_search_fallback(False).projection.fallback
    assert not on.with_controller("search").projection.fallback  # the search replaces the tracker outright
    res = run("generate", "a person jumps", "-o", tmp_path / "o", "--controller", "search", "--search-fallback")
    assert res.returncode == 1 and "--search-fallback is for the tracker" in res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "o").exists()


def test_the_flight_rescue_is_chosen_per_run(tmp_path: Path) -> None:
    """``--rescue-flights`` on or off per run; it needs the search of ``--recover`` and is not for the search
    controller; asking otherwise is one line before any work."""
    on = GenerateConfig().with_flight_rescue(True)
    assert on.projection.rescue_flight == 0.8 and on.with_flight_rescue(False).projection.rescue_flight == 0.0
    assert GenerateConfig().projection.rescue_flight == 0.0  # off by default
    with pytest.raises(PhysmotionError, match="--no-recover"):
        GenerateConfig().with_search_recovery(False).with_flight_rescue(True)
    for flags, said in ((["--no-recover"], "cannot be used with --no-recover"),
                        (["--controller", "search"], "--rescue-flights is for the tracker")):  # fmt: skip
        res = run("generate", "a person jumps", "-o", tmp_path / "o", *flags, "--rescue-flights")
        assert res.returncode == 1 and said in res.stderr
        assert "Traceback" not in res.stderr and not (tmp_path / "o").exists()


@pytest.mark.slow
def test_the_search_fallback_is_recorded_where_it_took_over(tiny_model, tmp_path: Path) -> None:
    """One P with the search as the tracker's fallback on the tiny model's run (which the tracker resets):
    the motions the search made say so in the .npz, in generate.json and in the summary, and
    carry no outside help."""
    from physmotion.generate import physics_summary
    from physmotion.physics.search import effort

    # without the recovery, which carries the falls the fallback is for
    projection = ProjectionConfig.sampling(fallback=True, recover=False, search=effort("fast"))
    cfg = _cfg(physics="post:1", projection=projection)
    result = generate(["a person runs fast and jumps"], cfg, tiny_model)
    write_outputs(result, tmp_path / "out", cfg, preview=False)
    (run,) = json.loads((tmp_path / "out" / "generate.json").read_text())["runs"]
    (entry,), (motion,) = run["motions"], result.motions
    back = Motion.load(tmp_path / "out" / entry["files"][0])
    print(f"\nsearched {motion.searched}, resets {motion.resets}; {physics_summary(result)}")
    assert motion.searched is True and entry["searched"] is True and back.searched is True
    assert "the search (no outside hand) made 1 of 1 motions" in physics_summary(result)
    assert not motion.residual.any() and not motion.residual_at_cap.any()


@pytest.mark.slow
def test_the_stretches_the_search_carried_are_recorded(tmp_path: Path) -> None:
    """The shipped model's hop of tests/physics/test_projection.py, generated with one P: the tracker resets
    it; with ``recover`` no reset, and the stretches the search carried counted in the motion, the .npz,
    generate.json and the summary; without ``recover`` the same request counts resets and no stretch."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.generate import physics_summary

    net = MotionDiffusion.load()
    cfg = GenerateConfig(seconds=4.0, physics="post:1", seed=2, projection=ProjectionConfig.sampling(recover=True))
    result = generate(["a child hops around happily"], cfg, net)
    plain = generate(["a child hops around happily"], cfg.with_search_recovery(False), net)
    write_outputs(result, tmp_path / "out", cfg, preview=False)
    (run,) = json.loads((tmp_path / "out" / "generate.json").read_text())["runs"]
    (entry,), (motion,) = run["motions"], result.motions
    back = Motion.load(tmp_path / "out" / entry["files"][0])
    print(f"\nrecovered {motion.recovered}, resets {motion.resets} (without: {plain.motions[0].resets}); "
          f"{physics_summary(result)}")
    # measured: 2 resets without; with recover 2 stretches carried and none reset (before a stretch carried to
    # the last step was kept, the body was put back there once)
    assert plain.motions[0].resets >= 1 and plain.motions[0].recovered == 0
    assert motion.resets == 0 and motion.recovered >= 1
    assert entry["recovered"] == back.recovered == motion.recovered and run["settings"]["projection"]["search_recover"]
    assert f"carried the body {motion.recovered} time(s)" in physics_summary(result)


def test_recover_is_refused_with_the_search_controller(tmp_path: Path) -> None:
    res = run("generate", "a person jumps", "-o", tmp_path / "o", "--controller", "search", "--recover")
    assert res.returncode == 1 and "--recover is for the tracker" in res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("texts", "config", "message"),
    [
        ([""], _cfg(), "empty"),
        (["walk"], _cfg(seconds=600), "seconds"),
        (["walk"], _cfg(seconds=float("nan")), "seconds"),
        (["walk"], {"physics": "physdiff:end:99,space:1"}, "schedule"),
        (["walk"], _cfg(num=0), "num"),
    ],
)
def test_bad_requests(tiny_model, texts, config, message) -> None:
    with pytest.raises(PhysmotionError, match=message):
        generate(texts, _cfg(**config) if isinstance(config, dict) else config, tiny_model)


@pytest.mark.parametrize("spelling", ["magic", "post:x", "post:0", "none:3", "physdiff:sideways:3"])
def test_bad_physics_modes(spelling: str) -> None:
    with pytest.raises(PhysmotionError, match="physics mode|post|schedule"):
        GenerateConfig(physics=spelling).physics.hook_steps(50)


def test_none_floor_grounds_each_motion_on_its_body_surface(tiny_model) -> None:
    """none+floor = none moved vertically by the constant that leaves the least Phys-Err on the body's
    surface: no worse than as sampled, nor than with its lowest surface point over the clip on y = 0."""
    from physmotion.metrics.physical import phys_err
    from physmotion.physics.surface import HumanoidSurface

    none = generate(["a person walks"], _cfg(num=2), tiny_model)
    floor = generate(["a person walks"], _cfg(num=2, physics="none+floor"), tiny_model)
    for a, b in zip(none.motions, floor.motions):
        shift = b.joints - a.joints
        assert np.allclose(shift[..., [0, 2]], 0) and np.allclose(shift[..., 1], shift[0, 0, 1], atol=1e-5)
        assert b.humanoid is not None and b.resets is None
        surface = HumanoidSurface(b.humanoid)
        lowest_on_floor = a.joints - [0, surface.lowest_height(a.joints.astype(np.float64)).min(), 0]
        grounded = phys_err(b.joints, body=surface)
        assert grounded <= phys_err(a.joints, body=surface) + 1e-6
        assert grounded <= phys_err(lowest_on_floor, body=surface) + 1e-6
    assert floor.projections.calls == 0


def test_slug() -> None:
    assert slug("A person walks forward.") == "a_person_walks_forward"
    assert slug("!!!") == "motion"


def test_cli_generate_writes_files(tiny_model_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "gen"
    res = run("generate", "a person walks forward", "--model", tiny_model_dir, "--seconds", "2",
              "--physics", "none", "--steps", "4", "-o", out)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert sorted(p.suffix for p in out.iterdir()) == [".bvh", ".gif", ".json", ".npz"]


def test_at_fine_step_halves_every_projections_step() -> None:
    config = GenerateConfig(physics="post:1", seed=3)
    fine = config.at_fine_step()
    for name in ("projection", "morph_projection"):
        assert getattr(fine, name) == getattr(config, name).at_fine_step()
    assert (fine.physics, fine.seed, fine.sampler) == (config.physics, config.seed, config.sampler)


def test_projected_motions_record_their_cap_and_torque_limits(tiny_model) -> None:
    """Each of P's outputs records the force cap of the P that made it (the sampling preset's 0.3 W for
    post and physdiff, the plain 0.2 W for morph) and its frames over the torque limit, so that a reader
    of the file alone can tell the share at the cap; motions P did not make record neither."""
    from physmotion.metrics.report import residual_summary

    for physics, cap in (("post:1", 0.3), ("physdiff:end:2,space:1", 0.3), ("morph", 0.2)):
        out = generate(["a person walks"], _cfg(physics=physics, num=2), tiny_model)
        for m in out.motions:
            if m.residual is None:  # morph's selection kept the sampled motion
                assert m.residual_cap is None and m.over_limit is None
                continue
            assert m.residual_cap == pytest.approx(cap) and m.over_limit.shape == (m.num_frames,)
            row = residual_summary(m)
            # every update's caps (force, lift, torque) count: at least the frames whose mean force is at its cap
            assert row["residual_at_cap"] == pytest.approx(m.residual_at_cap.mean())
            assert np.all(m.residual_at_cap[m.residual[:, 0] >= 0.99 * cap])
            assert np.all(m.residual_peak >= m.residual - 1e-6) and m.reset_frames.shape == (m.num_frames,)
            assert row["over_limit"] == pytest.approx(m.over_limit.mean())
    plain = generate(["a person walks"], _cfg(), tiny_model).motions[0]
    assert plain.residual_cap is None and plain.over_limit is None and residual_summary(plain) == {}


def test_cli_generate_fine_step_is_another_projection_and_is_logged(tiny_model_dir: Path, tmp_path: Path) -> None:
    """``--fine-step`` simulates P at 1/720 s: the run log says so, and the projected motion differs."""
    joints = {}
    for name, extra in (("plain", []), ("fine", ["--fine-step"])):
        out = tmp_path / name
        res = run("generate", "a person walks forward", "--model", tiny_model_dir, "--seconds", "2", "--physics",
                  "post:1", "--no-recover", "--steps", "4", "--no-preview", "-o", out, *extra)  # fmt: skip
        assert res.returncode == 0, res.stderr
        settings = json.loads((out / "generate.json").read_text())["runs"][-1]["settings"]
        step = 1 / 720 if extra else 1 / 360
        assert settings["projection"]["sim_dt"] == pytest.approx(step)
        assert settings["morph_projection"]["sim_dt"] == pytest.approx(step)
        joints[name] = Motion.load(next(out.glob("*.npz"))).joints
    assert joints["plain"].shape == joints["fine"].shape and not np.array_equal(joints["plain"], joints["fine"])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["", "--seconds", "2"], "text is empty"),
        (["walk", "--seconds", "1000"], "--seconds must be between"),
        (["walk", "--physics", "physdiff:sideways:3"], "bad schedule"),
        (["walk", "--physics", "magic"], "unknown physics mode"),
    ],
)
def test_cli_bad_input_is_one_line_and_writes_nothing(tiny_model_dir: Path, tmp_path: Path, args, message) -> None:
    out = tmp_path / "gen"
    res = run("generate", *args, "--model", tiny_model_dir, "-o", out)
    assert res.returncode == 1 and message in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
    assert not out.exists()


def test_cli_missing_checkpoint(tmp_path: Path) -> None:
    res = run("generate", "walk", "--model", tmp_path / "nope", "-o", tmp_path / "gen")
    assert res.returncode == 1 and "no model checkpoint" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "gen").exists()


def test_a_329d_model_projects_in_its_own_features(imported_clips) -> None:
    """BioMoDiffuse's 329-d features through post and physdiff: P's output is re-extracted as 329-d and
    normalised with the model's own 329-d statistics (a 263-d re-extraction used to crash here).
    The denoiser has random weights; its statistics come from real clips."""
    import torch

    from physmotion.nets.denoiser import DenoiserConfig, build_denoiser
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.schedule import DiffusionConfig
    from physmotion.features.biomech import FEATURE_DIM_BIOMECH, extract_features_329
    from physmotion.features.normalize import Normalizer, compute_mean_std

    clips = [m for m in imported_clips.values() if isinstance(m, Motion)][:12]
    mean, std = compute_mean_std([extract_features_329(m.joints)[0] for m in clips])
    den = DenoiserConfig(feature_dim=FEATURE_DIM_BIOMECH, d_model=32, layers=1)
    torch.manual_seed(0)
    model = MotionDiffusion(net=build_denoiser(den).eval(), denoiser=den, diffusion=DiffusionConfig(),
                            normalizer=Normalizer(mean, std), info={"licence_tags": ["NC"]})
    for mode in ("post:1", "physdiff:end:2,space:1"):
        out = generate(["a person walks"], _cfg(physics=mode), model)
        assert out.projections.calls >= 1 and out.features[0].shape == (48, FEATURE_DIM_BIOMECH), mode
        assert out.motions[0].joints.shape == (48, 22, 3) and out.bodies[0] is not None, mode
        assert out.motions[0].resets is not None and out.motions[0].resets >= 0


def test_morph_mode_is_one_projection_with_imitation_selection(tiny_model) -> None:
    """morph: plain sampling, App. A's pre-processing, then one P that keeps the (pre-processed) sampled
    motion where the imitation fails (Morph Sec. 3.3 "Inference"); failures are counted apart from resets."""
    from physmotion.eval.physics_columns import imitation_columns
    from physmotion.morph.preprocess import PreprocessConfig, floor_first_frame, preprocess
    from physmotion.pipelines.modes import PhysicsMode, parse_modes

    mode = PhysicsMode.parse("morph")
    assert str(mode) == "morph" and mode.projects and mode.projections == 1 and mode.hook_steps(50) == []
    assert [str(m) for m in parse_modes("none,morph,post:2")] == ["none", "morph", "post:2"]
    with pytest.raises(PhysmotionError, match="unknown physics mode"):
        PhysicsMode.parse("morph:2")
    cfg = _cfg(physics="morph", num=2)
    assert not cfg.morph_projection.reset_on_fail and cfg.morph_projection.tau == 0.5
    morph = generate(["a person walks"], cfg, tiny_model)
    none = generate(["a person walks"], _cfg(num=2), tiny_model)
    assert morph.projections.calls == 1 and len(morph.imitation_failed) == 2 and none.imitation_failed == []
    for m, n, failed, body in zip(morph.motions, none.motions, morph.imitation_failed, morph.bodies):
        assert failed == (body is None)  # a kept input was not simulated on a body
        if failed:  # the sampled motion after App. A's pre-processing, its first frame on the floor
            kept = floor_first_frame(preprocess(n.joints, PreprocessConfig()), physical=True)
            assert np.allclose(m.joints, kept, atol=1e-5)
    assert imitation_columns([morph]) == {"imitation_failure_rate": float(np.mean(morph.imitation_failed))}
    assert imitation_columns([none]) == {}


@pytest.mark.slow  # two console-script processes with the shipped model (about 40 s)
def test_console_script_generate_morph_writes_the_same_files(tmp_path: Path) -> None:
    """The installed console script, the shipped model: morph writes what the other modes write, and its
    imitation failures go to generate.json."""
    import subprocess
    import sys

    exe = Path(sys.executable).parent / "physmotion"
    names = {}
    for mode in ("none", "morph"):
        out = tmp_path / mode
        res = subprocess.run([str(exe), "generate", "a person walks forward", "--seconds", "2", "--steps", "5",
                              "--physics", mode, "-o", str(out)], capture_output=True, text=True, timeout=600,
                             check=False)  # fmt: skip
        assert res.returncode == 0, res.stderr
        names[mode] = sorted(p.name for p in out.iterdir())
    assert names["morph"] == names["none"]
    run_log = json.loads((tmp_path / "morph" / "generate.json").read_text())["runs"][-1]
    assert run_log["settings"]["physics"] == "morph"
    assert run_log["settings"]["morph_projection"] == {"reset_on_fail": False, "tau": 0.5, "sim_dt": 1 / 360,
                                                       "search_fallback": False, "search_recover": False,
                                                       "flight_rescue": 0.0}
    assert run_log["projections"]["imitation_failures"] in (0, 1)
    assert 0.0 <= run_log["projections"]["imitation_failure_rate"] <= 1.0
    assert isinstance(run_log["motions"][0]["imitation_failed"], bool)


def test_shipped_model_names_work_from_any_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--model base``, ``morph`` and ``default`` name the shipped folders wherever the user stands; the
    default is the Morph-tuned model, and ``generate.json`` records which one made the motions."""
    from physmotion.cli._common import _model_dir
    from physmotion.diffusion.model import BASE_MODEL_DIR, DEFAULT_MODEL_DIR

    monkeypatch.chdir(tmp_path)
    assert _model_dir(Path("base")) == BASE_MODEL_DIR and _model_dir(Path("morph")) == DEFAULT_MODEL_DIR
    assert _model_dir(Path("default")) == DEFAULT_MODEL_DIR and DEFAULT_MODEL_DIR.name == "morph"
    assert _model_dir(None) is None and _model_dir(Path("nosuch")) == Path("nosuch")  # left to the loader's error
    (tmp_path / "base").mkdir()  # a folder of that name here wins over the shipped one
    assert _model_dir(Path("base")) == Path("base")
    res = run("generate", "a person walks forward", "--seconds", "2", "--steps", "2", "--physics", "none",
              "--model", "nosuch", "-o", tmp_path / "x")  # fmt: skip
    assert res.returncode == 1 and "nosuch" in res.stderr and "Traceback" not in res.stderr
