"""Shared fixtures: the real mocap folder, every manifest clip imported and the dataset built once per
session, and tiny training runs on it."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from physmotion.data.build import BuildConfig, BuildReport, build_dataset
from physmotion.diffusion.denoiser import DenoiserConfig
from physmotion.diffusion.train import TrainConfig

MOCAP_DIR = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap"


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: runs over the whole mocap manifest (seconds); still run in CI")


@pytest.fixture(scope="session")
def mocap_dir() -> Path:
    """``../shared/data/mocap`` next to the repository; a failure, not a skip, when it is missing."""
    if not (MOCAP_DIR / "manifest.csv").is_file():
        pytest.fail(f"the mocap data is missing: expected {MOCAP_DIR.resolve()}/manifest.csv")
    return MOCAP_DIR.resolve()


@pytest.fixture(scope="session")
def import_results(mocap_dir: Path) -> dict[str, object]:
    """clip id -> (Motion, ImportReport), or the one-line error message; imports the manifest once.

    The wall time of the whole import is stored under the key ``"__seconds__"``.
    """
    from physmotion.errors import PhysmotionError
    from physmotion.io import import_clip_with_report, load_manifest

    results: dict[str, object] = {}
    start = time.perf_counter()
    for info in load_manifest(mocap_dir):
        try:
            results[info.clip] = import_clip_with_report(info)
        except PhysmotionError as exc:
            results[info.clip] = str(exc)
    results["__seconds__"] = time.perf_counter() - start
    return results


@pytest.fixture(scope="session")
def imported_clips(import_results: dict[str, object]) -> dict[str, object]:
    """clip id -> Motion, or the one-line error message for clips that failed to import."""
    return {
        k: v[0] if isinstance(v, tuple) else v for k, v in import_results.items() if not k.startswith("__")
    }


@pytest.fixture(scope="session")
def built(tmp_path_factory: pytest.TempPathFactory, mocap_dir: Path) -> BuildReport:
    """The whole mocap collection built with the default options (about 12 s)."""
    out = tmp_path_factory.mktemp("build") / "mocap"
    return build_dataset(mocap_dir, out, BuildConfig(), progress=False)


@pytest.fixture(scope="session")
def built_dir(built: BuildReport) -> Path:
    return built.out


# --- tiny training runs on the real bundled data (diffusion and generation tests) ---


def tiny_config(data: Path, out: Path, **kw) -> TrainConfig:
    """A small transformer that trains in seconds on 2 CPU cores."""
    den = DenoiserConfig(d_model=kw.pop("d_model", 64), layers=kw.pop("layers", 2), heads=4, dropout=0.1)
    base = {"batch_size": 8, "crop": 64, "steps": 20, "lr": 1e-3, "warmup": 5, "log_every": 5, "checkpoint_minutes": 60.0}
    base.update(kw)
    return TrainConfig(data=str(data), out=str(out), denoiser=den, **base)


@pytest.fixture(scope="session")
def one_clip_dir(built_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A HumanML3D-layout folder whose train split is one real walking window, eight times over."""
    out = tmp_path_factory.mktemp("one_clip")
    for sub in ("new_joint_vecs", "texts"):
        (out / sub).mkdir()
    ids = (built_dir / "train.txt").read_text().split()
    pick = next(i for i in ids if "walk_normal" in i and not i.startswith("M"))
    feats = np.load(built_dir / "new_joint_vecs" / f"{pick}.npy")[:64]
    names = [f"copy{k}" for k in range(8)]
    for name in names:
        np.save(out / "new_joint_vecs" / f"{name}.npy", feats)
        (out / "texts" / f"{name}.txt").write_text("a person walks forward\n")
    (out / "train.txt").write_text("\n".join(names) + "\n")
    for f in ("Mean.npy", "Std.npy", "build_info.json"):
        shutil.copy(built_dir / f, out / f)
    return out


@pytest.fixture(scope="session")
def tiny_model_dir(built_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny denoiser trained for a few steps on the bundled data: real weights, not a useful model."""
    from physmotion.diffusion.train import train_denoiser

    out = tmp_path_factory.mktemp("tiny_model")
    train_denoiser(tiny_config(built_dir, out, steps=10, d_model=32, layers=1), progress=False)
    return out


@pytest.fixture(scope="session")
def tiny_model(tiny_model_dir: Path):
    from physmotion.diffusion.model import MotionDiffusion

    return MotionDiffusion.load(tiny_model_dir)


def tiny_evaluator_config(data: Path, out: Path, **kw):
    """A small evaluator that trains 3 epochs in seconds on 2 CPU cores (an EvaluatorTrainConfig)."""
    from physmotion.eval.evaluator import EvaluatorConfig
    from physmotion.eval.train import EvaluatorTrainConfig

    base = {"epochs": 3, "eval_every": 1, "eval_repeats": 2, "lr": 5e-4,
            "evaluator": EvaluatorConfig(d_model=32, motion_layers=1, text_layers=1, latent_dim=16)}  # fmt: skip
    base.update(kw)
    return EvaluatorTrainConfig(data=str(data), out=str(out), **base)


@pytest.fixture(scope="session")
def tiny_evaluator_dir(built_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small evaluator trained for 3 epochs on the bundled data: real weights, a weak evaluator."""
    from physmotion.eval.train import train_evaluator

    out = tmp_path_factory.mktemp("tiny_evaluator") / "evaluator"
    train_evaluator(tiny_evaluator_config(built_dir, out), progress=False)
    return out


@pytest.fixture(scope="session")
def tiny_evaluator(tiny_evaluator_dir: Path):
    from physmotion.eval.evaluator import Evaluator

    return Evaluator.load(tiny_evaluator_dir)


# --- BioMoDiffuse (arch "biomo"): the 329-d build with its activation cache, and a tiny model on it ---


@pytest.fixture(scope="session")
def built329_dir(tmp_path_factory: pytest.TempPathFactory, mocap_dir: Path) -> Path:
    """The whole mocap collection built with 329-d features (``BuildConfig(features=329)``) and its
    muscle-activation cache, as ``data build --features 329 --activations`` makes it (about 30 s)."""
    from physmotion.data.build import build_activations

    out = tmp_path_factory.mktemp("build329") / "mocap"
    build_dataset(mocap_dir, out, BuildConfig(features=329), progress=False)
    build_activations(out, progress=False)
    return out


def tiny_biomo_config(data: Path, out: Path, **kw) -> TrainConfig:
    """A small BioMoDiffuse denoiser (1D UNet + physical network) that trains in seconds on 2 CPU cores."""
    den = DenoiserConfig(arch="biomo", feature_dim=329, d_model=kw.pop("d_model", 32), layers=kw.pop("layers", 2),
                         heads=4, dropout=0.1, phys_hidden=kw.pop("phys_hidden", 32))  # fmt: skip
    base = {"batch_size": 4, "crop": 40, "steps": 10, "lr": 1e-3, "warmup": 2, "log_every": 5,
            "checkpoint_minutes": 60.0}  # fmt: skip
    base.update(kw)
    return TrainConfig(data=str(data), out=str(out), denoiser=den, **base)


@pytest.fixture(scope="session")
def tiny_biomo_dir(built329_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny biomo model trained for 10 steps on the 329-d build: real weights, not a useful model."""
    from physmotion.diffusion.train import train_denoiser

    out = tmp_path_factory.mktemp("tiny_biomo")
    train_denoiser(tiny_biomo_config(built329_dir, out), progress=False)
    return out


@pytest.fixture(scope="session")
def tiny_biomo(tiny_biomo_dir: Path):
    from physmotion.diffusion.model import MotionDiffusion

    return MotionDiffusion.load(tiny_biomo_dir)
