"""Shared fixtures: the real mocap folder, every manifest clip imported and the dataset built once per
session, and tiny training runs on it.

Two tiers (see tests/README.md): the default ``pytest`` deselects tests marked ``slow``; ``make test``
runs both, in two pytest-xdist workers. A test whose fixtures build or import the whole mocap collection
(``built``, ``built_dir``, ``built329_dir``, ``import_results``, ``imported_clips``, and HDM05's
``hdm05_results``) is marked slow here
(:func:`pytest_collection_modifyitems`); the fast tier builds :data:`SMALL_CLIPS`, a few real clips
of every source and split, instead (``small_built_dir``, ``small_built329_dir``), and trains its tiny
denoisers on them (the tiny evaluator needs the whole build: retrieval takes 32 motions per split).

Every directory fixture of a whole session is built once per test run, whatever the number of xdist
workers: the first worker builds it under a file lock in the run's shared temporary folder, the others
wait for it and read it (:func:`_shared_dir`). Tests only read these folders.
"""

from __future__ import annotations

import contextlib
import csv
import os
import pickle
import shutil
import subprocess
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from physmotion.data.build import BuildConfig, BuildReport, build_dataset
from physmotion.diffusion.train import TrainConfig
from physmotion.imitator.clips import dataset_clips
from physmotion.imitator.teacher import TeacherConfig, TeacherJob, search_job
from physmotion.nets.denoiser import DenoiserConfig
from physmotion.physics.search import SearchConfig

MOCAP_DIR = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap"
HDM05_DIR = MOCAP_DIR.parent / "hdm05"


# Fixtures that import or build the whole mocap collection (minutes on 2 cores): their tests are slow.
WHOLE_COLLECTION = frozenset({"import_results", "imported_clips", "built", "built_dir", "built329_dir",
                              "hdm05_results", "built_all", "built_all_dir"})  # fmt: skip


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: runs over the whole mocap manifest (seconds); still run in CI")
    # On-disk caches (prompt embeddings, physmotion/text/encoder.py) go to a folder of this run, never the
    # user's ~/.cache/physmotion; processes the tests start inherit it.
    if "PHYSMOTION_CACHE_DIR" not in os.environ:
        import tempfile

        cache = tempfile.mkdtemp(prefix="physmotion-test-cache-")
        os.environ["PHYSMOTION_CACHE_DIR"] = cache
        config.add_cleanup(lambda: shutil.rmtree(cache, ignore_errors=True))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark slow every test that needs the whole collection imported or built."""
    for item in items:
        if WHOLE_COLLECTION.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    from filelock import FileLock

    with FileLock(str(path) + ".lock"):
        yield


def _run_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The temporary folder all xdist workers of this run share (each worker's basetemp is under it)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def _shared_dir(tmp_path_factory: pytest.TempPathFactory, name: str, make: Callable[[Path], None]) -> Path:
    """``<run root>/shared/<name>``, made once per test run by ``make(folder)``: under xdist the first
    worker to ask makes it while holding a lock, the others wait and reuse it. ``make`` writes into the
    empty folder it is given; a ``.done`` file marks it complete, so a failed attempt is retried."""
    root = _run_root(tmp_path_factory) / "shared"
    root.mkdir(exist_ok=True)
    folder = root / name
    with _locked(folder):
        if not (folder / ".done").is_file():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            make(folder)
            (folder / ".done").write_text("")
    return folder


def run_git(repo: Path, *args: str) -> str:
    """``git *args`` in ``repo`` (an identity given, so commits work on a machine with none); its stdout."""
    res = subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@example.org", *args], cwd=repo,
                         capture_output=True, text=True, check=True)  # fmt: skip
    return res.stdout.strip()


@pytest.fixture
def git_repo(tmp_path: Path) -> Path:
    """A real git repository with one committed file, ``code.py``."""
    root = tmp_path / "repo"
    root.mkdir()
    run_git(root, "init", "-q")
    (root / "code.py").write_text("x = 1\n")
    run_git(root, "add", "code.py")
    run_git(root, "commit", "-q", "-m", "first")
    return root


@pytest.fixture(scope="session")
def mocap_dir() -> Path:
    """``../shared/data/mocap`` next to the repository; a failure, not a skip, when it is missing."""
    if not (MOCAP_DIR / "manifest.csv").is_file():
        pytest.fail(f"the mocap data is missing: expected {MOCAP_DIR.resolve()}/manifest.csv")
    return MOCAP_DIR.resolve()


@pytest.fixture(scope="session")
def hdm05_dir() -> Path:
    """``../shared/data/hdm05`` (HDM05's ASF/AMC clips, Latin-1 headers); a failure when missing."""
    if not (HDM05_DIR / "manifest.csv").is_file():
        pytest.fail(f"the HDM05 data is missing: expected {HDM05_DIR.resolve()}/manifest.csv")
    return HDM05_DIR.resolve()


@pytest.fixture(scope="session")
def import_results(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """clip id -> (Motion, ImportReport), or the one-line error message; imports the manifest once.

    The wall time of the whole import is stored under the key ``"__seconds__"``.
    """
    from physmotion.errors import PhysmotionError
    from physmotion.io import import_clip_with_report, load_manifest

    def make(folder: Path) -> None:
        results: dict[str, object] = {}
        start = time.perf_counter()
        for info in load_manifest(mocap_dir):
            try:
                results[info.clip] = import_clip_with_report(info)
            except PhysmotionError as exc:
                results[info.clip] = str(exc)
        results["__seconds__"] = time.perf_counter() - start
        (folder / "results.pickle").write_bytes(pickle.dumps(results))

    # Imported once per run; xdist workers other than the first read the pickled results.
    return pickle.loads((_shared_dir(tmp_path_factory, "import", make) / "results.pickle").read_bytes())


@pytest.fixture(scope="session")
def imported_clips(import_results: dict[str, object]) -> dict[str, object]:
    """clip id -> Motion, or the one-line error message for clips that failed to import."""
    return {
        k: v[0] if isinstance(v, tuple) else v for k, v in import_results.items() if not k.startswith("__")
    }


WHOLE_BUILD = BuildConfig(pad_short=False)
"""The options of the whole-collection fixtures: those of ``make data``'s ``data_build/mocap``, the build the
shipped models trained on (short clips skipped, not held to 2 s), so their vocabulary and counts match."""


@pytest.fixture(scope="session")
def built(tmp_path_factory: pytest.TempPathFactory, mocap_dir: Path) -> BuildReport:
    """The whole mocap collection built as the shipped models' training data was (about 12 s on 8 cores,
    1-2 min on 2): :data:`WHOLE_BUILD`."""

    def make(folder: Path) -> None:
        report = build_dataset(mocap_dir, folder / "mocap", WHOLE_BUILD, progress=False)
        (folder / "report.pickle").write_bytes(pickle.dumps(report))

    return pickle.loads((_shared_dir(tmp_path_factory, "build", make) / "report.pickle").read_bytes())


@pytest.fixture(scope="session")
def built_dir(built: BuildReport) -> Path:
    return built.out


@pytest.fixture(scope="session")
def built_all(tmp_path_factory: pytest.TempPathFactory, mocap_dir: Path, hdm05_dir: Path) -> BuildReport:
    """Both collections, mocap and HDM05, built as the shipped default model's training data was
    (``physmotion data build --source ../shared/data/mocap --source ../shared/data/hdm05``, the command's
    defaults; about 40 s on 2 cores)."""

    def make(folder: Path) -> None:
        report = build_dataset([mocap_dir, hdm05_dir], folder / "all", BuildConfig(), progress=False)
        (folder / "report.pickle").write_bytes(pickle.dumps(report))

    return pickle.loads((_shared_dir(tmp_path_factory, "build_all", make) / "report.pickle").read_bytes())


@pytest.fixture(scope="session")
def built_all_dir(built_all: BuildReport) -> Path:
    return built_all.out


# --- the fast tier's data: a build of a few real clips of every source and split ---

SMALL_CLIPS = (
    # train
    "bandai2_dataset-2_walk_normal_001", "bandai2_dataset-2_run_normal_001",
    "bandai2_dataset-2_wave-right-hand_normal_001", "bandai2_dataset-2_walk-turn-left_normal_001",
    "bandai1_dataset-1_bow_active_001", "cmu_02_01", "cmuiclone_02_01",
    "cmu_02_03",  # 29 frames, under the 2 s minimum: the build's short-clip rule applies
    "bandai2_dataset-2_walk_normal_002", "bandai2_dataset-2_walk_normal_003", "bandai2_dataset-2_run_normal_002",
    "bandai2_dataset-2_run_normal_003",
    "bandai2_dataset-2_walk-turn-left_normal_002", "bandai2_dataset-2_walk-turn-right_normal_002",
    "bandai2_dataset-2_walk-turn-right_normal_003", "bandai2_dataset-2_wave-right-hand_masculine_001",
    "bandai2_dataset-2_wave-both-hands_normal_001",  # a train split of at least a batch (32 motions)
    # val
    "bandai2_dataset-2_walk-turn-left_youthful_001", "bandai2_dataset-2_wave-both-hands_masculine_001",
    "bandai2_dataset-2_walk_feminine_001",
    # test
    "bandai2_dataset-2_walk-turn-right_normal_001", "bandai2_dataset-2_wave-left-hand_elderly_001",
    "bandai2_dataset-2_wave-right-hand_feminine_001",
)  # fmt: skip


def small_manifest(mocap_dir: Path, out: Path, clips: tuple[str, ...] = SMALL_CLIPS) -> Path:
    """A mocap folder ``out`` whose manifest lists only ``clips`` of ``mocap_dir``'s, with absolute
    paths into ``mocap_dir`` (nothing is copied)."""
    out.mkdir(parents=True, exist_ok=True)
    with open(mocap_dir / "manifest.csv", newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        rows = [r for r in reader if r["clip"] in clips]
        fields = reader.fieldnames
    assert sorted(r["clip"] for r in rows) == sorted(clips), "a clip of the small set left the manifest"
    for r in rows:
        r["path"] = str(mocap_dir / r["path"])
        if r["format"].lower() == "amc":
            r["skeleton"] = str(mocap_dir / r["skeleton"])
    with open(out / "manifest.csv", "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    return out


@pytest.fixture(scope="session")
def small_mocap_dir(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A mocap folder of the :data:`SMALL_CLIPS` (a manifest pointing into ../shared/data/mocap)."""
    return _shared_dir(tmp_path_factory, "small_mocap", lambda folder: small_manifest(mocap_dir, folder))


@pytest.fixture(scope="session")
def small_built_dir(small_mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """:data:`SMALL_CLIPS` built with the default options: every split, both licence tags, mirrors."""

    def make(folder: Path) -> None:
        build_dataset(small_mocap_dir, folder / "mocap", BuildConfig(jobs=1), progress=False)

    return _shared_dir(tmp_path_factory, "small_build", make) / "mocap"


@pytest.fixture(scope="session")
def small_built329_dir(small_mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """:data:`SMALL_CLIPS` built with 329-d features and the muscle-activation cache."""
    from physmotion.data.build import build_activations

    def make(folder: Path) -> None:
        build_dataset(small_mocap_dir, folder / "mocap", BuildConfig(features=329, jobs=1), progress=False)
        build_activations(folder / "mocap", progress=False, jobs=1)

    return _shared_dir(tmp_path_factory, "small_build329", make) / "mocap"


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

    def make(out: Path) -> None:
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

    return _shared_dir(tmp_path_factory, "one_clip", lambda folder: make(_mkdir(folder / "data"))) / "data"


def _mkdir(path: Path) -> Path:
    path.mkdir()
    return path


@pytest.fixture(scope="session")
def tiny_model_dir(small_built_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny denoiser trained for a few steps on the small build: real weights, not a useful model."""
    from physmotion.diffusion.train import train_denoiser

    def make(folder: Path) -> None:
        train_denoiser(tiny_config(small_built_dir, folder / "model", steps=10, d_model=32, layers=1),
                       progress=False)  # fmt: skip

    return _shared_dir(tmp_path_factory, "tiny_model", make) / "model"


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
    """A small evaluator trained for 3 epochs on the bundled data: real weights, a weak evaluator.

    On the whole build (so its tests are slow): retrieval on val and test needs 32 motions in each split,
    more than a few clips give."""
    from physmotion.eval.train import train_evaluator

    def make(folder: Path) -> None:
        train_evaluator(tiny_evaluator_config(built_dir, folder / "evaluator"), progress=False)

    return _shared_dir(tmp_path_factory, "tiny_evaluator", make) / "evaluator"


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

    def make(folder: Path) -> None:
        build_dataset(mocap_dir, folder / "mocap", replace(WHOLE_BUILD, features=329), progress=False)
        build_activations(folder / "mocap", progress=False)

    return _shared_dir(tmp_path_factory, "build329", make) / "mocap"


def tiny_biomo_config(data: Path, out: Path, **kw) -> TrainConfig:
    """A small BioMoDiffuse denoiser (1D UNet + physical network) that trains in seconds on 2 CPU cores."""
    den = DenoiserConfig(arch="biomo", feature_dim=329, d_model=kw.pop("d_model", 32), layers=kw.pop("layers", 2),
                         heads=4, dropout=0.1, phys_hidden=kw.pop("phys_hidden", 32))  # fmt: skip
    base = {"batch_size": 4, "crop": 40, "steps": 10, "lr": 1e-3, "warmup": 2, "log_every": 5,
            "checkpoint_minutes": 60.0}  # fmt: skip
    base.update(kw)
    return TrainConfig(data=str(data), out=str(out), denoiser=den, **base)


@pytest.fixture(scope="session")
def tiny_biomo_dir(small_built329_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny biomo model trained for 10 steps on the small 329-d build: real weights, not a useful model."""
    from physmotion.diffusion.train import train_denoiser

    def make(folder: Path) -> None:
        train_denoiser(tiny_biomo_config(small_built329_dir, folder / "model"), progress=False)

    return _shared_dir(tmp_path_factory, "tiny_biomo", make) / "model"


@pytest.fixture(scope="session")
def tiny_biomo(tiny_biomo_dir: Path):
    from physmotion.diffusion.model import MotionDiffusion

    return MotionDiffusion.load(tiny_biomo_dir)


# The search at a tiny effort: enough to carry 1 s of a walk with no outside hand in a few seconds.
TINY_TEACHER = TeacherConfig(search=SearchConfig(candidates=4, rounds=1, elites=2, horizon=3))


@pytest.fixture(scope="session")
def teacher_dir(small_built_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A teacher folder holding one record: the first second of a captured walk, searched from a plain
    start."""

    def make(folder: Path) -> None:
        train = dataset_clips(small_built_dir, "train")
        src = next(c for c in train if "_walk_" in c.name and c.name[0] != "M")
        joints = src.joints[: int(src.fps)].astype(np.float64)
        job = TeacherJob(src.name, src.origin, src.licence_tag, 0, joints, src.fps, np.zeros(6))
        folder.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(folder / f"{job.id}.npz", **search_job(job, TINY_TEACHER))

    return _shared_dir(tmp_path_factory, "teacher_walk", make)
