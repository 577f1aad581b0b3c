"""One dataset from several sources (``data build --source A --source B``): every clip of each manifest,
a capture on one side of the split, every licence tag and each source's README carried along, minutes
per source. Counts come from the manifests, never written here."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

from physmotion.data.build import BuildReport, build_dataset, capture_of, source_names
from physmotion.errors import PhysmotionError
from physmotion.io import ClipInfo, load_manifest


def _index(root: Path) -> list[dict[str, str]]:
    with open(root / "index.csv", newline="") as f:
        return list(csv.DictReader(f))


def _subset(folder: Path, out: Path, keep: int) -> Path:
    """A source folder whose manifest lists every ``keep``-th clip of ``folder``'s (paths made absolute)."""
    out.mkdir(parents=True)
    with open(folder / "manifest.csv", newline="") as f:
        reader = csv.DictReader(f)
        rows, fields = list(reader)[::keep], reader.fieldnames
    for r in rows:
        r["path"] = str(folder / r["path"])
        if r["format"] == "amc":
            r["skeleton"] = str(folder / r["skeleton"])
    with open(out / "manifest.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    (out / "README.md").write_text(f"subset of {folder}\n")
    return out


def test_hdm05_segments_of_one_actor_and_class_are_one_capture(hdm05_dir: Path) -> None:
    clips = load_manifest(hdm05_dir)
    groups: dict[str, set[str]] = defaultdict(set)
    for c in clips:
        actor, label = c.path.stem.split("_")[1:3]
        groups[capture_of(c)].add(f"{actor}/{label}")
    assert all(len(v) == 1 for v in groups.values())  # a capture is one actor and one class ...
    assert len(groups) < len(clips) and len({c.take for c in clips}) == len(clips)  # ... the manifest's takes are clips


def test_other_takes_are_the_manifests(mocap_dir: Path) -> None:
    assert all(capture_of(c) == c.take for c in load_manifest(mocap_dir))
    assert source_names([Path("a/mocap"), Path("b/hdm05")]) == ["mocap", "hdm05"]
    assert source_names([Path("a/x"), Path("b/x")]) == ["a/x", "b/x"]


def test_clip_ids_must_differ_across_sources(mocap_dir: Path, tmp_path: Path) -> None:
    copy = _subset(mocap_dir, tmp_path / "copy", 50)
    with pytest.raises(PhysmotionError, match="is in both mocap and copy"):
        build_dataset([mocap_dir, copy], tmp_path / "out", progress=False)
    with pytest.raises(PhysmotionError, match="given twice"):
        build_dataset([copy, copy], tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()


@pytest.mark.slow  # starts a process
def test_cli_builds_two_sources(mocap_dir: Path, hdm05_dir: Path, tmp_path: Path) -> None:
    """The summary names each source with its clips, minutes and licences; Latin-1 files get one line."""
    a = _subset(mocap_dir, tmp_path / "mocap", 60)
    b = _subset(hdm05_dir, tmp_path / "hdm05", 40)
    out = tmp_path / "both"
    done = subprocess.run([sys.executable, "-m", "physmotion.cli", "data", "build", "--source", str(a), "--source",
                           str(b), "-o", str(out), "--jobs", "1"], capture_output=True, text=True, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr
    per_source = {line.split(":")[0].strip(): line for line in done.stdout.splitlines() if line.startswith("  ")}
    assert set(per_source) == {"mocap", "hdm05"}
    hdm05 = load_manifest(b)
    assert f"{len(hdm05)}/{len(hdm05)} clips" in per_source["hdm05"] and "SA (CC-BY-SA-3.0)" in per_source["hdm05"]
    warnings = [ln for ln in done.stderr.splitlines() if ln.strip()]
    n = len(hdm05)
    assert warnings == [f"warning: {n} clips' files are not UTF-8 and were read as Latin-1 (hdm05 {n})"]
    info = json.loads((out / "build_info.json").read_text())
    assert info["source"] == [str(a), str(b)] and set(info["sources"]) == {"mocap", "hdm05"}
    assert (out / "sources" / "hdm05.md").read_text() == f"subset of {hdm05_dir}\n"


# --- the whole of both collections, as `make data` builds them ---


@pytest.fixture(scope="module")
def both(built_all: BuildReport) -> BuildReport:
    return built_all  # conftest.py's build of both collections, shared with the shipped model's tests


@pytest.mark.slow
def test_every_hdm05_clip_builds(both: BuildReport, hdm05_dir: Path) -> None:
    hdm05 = load_manifest(hdm05_dir)
    assert not [c.clip for c in hdm05 if c.clip in both.skipped]
    src = both.sources["hdm05"]
    assert src.clips == src.built == src.latin1 == len(hdm05) and src.licences == {"SA": ["CC-BY-SA-3.0"]}
    assert {r["clip"] for r in _index(both.out) if r["source"] == "hdm05"} == {c.clip for c in hdm05}
    print("\n" + "; ".join(f"{n}: {s.built}/{s.clips} clips, {s.minutes:.2f} min" for n, s in both.sources.items()))


@pytest.mark.slow
def test_minutes_per_source_add_up(both: BuildReport) -> None:
    assert all(s.minutes > 0 for s in both.sources.values())
    assert sum(s.minutes for s in both.sources.values()) == pytest.approx(both.minutes, rel=1e-9)
    info = json.loads((both.out / "build_info.json").read_text())
    assert {n: s["minutes"] for n, s in info["sources"].items()} == {
        n: round(s.minutes, 3) for n, s in both.sources.items()
    }


@pytest.mark.slow
def test_every_licence_tag_is_carried(both: BuildReport, mocap_dir: Path, hdm05_dir: Path) -> None:
    manifest: list[ClipInfo] = [*load_manifest(mocap_dir), *load_manifest(hdm05_dir)]
    tag_of = {c.clip: c.licence_tag for c in manifest}
    rows = _index(both.out)
    assert all(r["licence_tag"] == tag_of[r["clip"]] for r in rows)
    info = json.loads((both.out / "build_info.json").read_text())
    assert info["licence_tags"] == sorted({c.licence_tag or "open" for c in manifest})
    assert {"NC", "SA"} <= set(info["licence_tags"])
    for name in ("mocap", "hdm05"):  # each source's README (attribution, licence terms) goes with the data
        folder = mocap_dir if name == "mocap" else hdm05_dir
        assert (both.out / "sources" / f"{name}.md").read_bytes() == (folder / "README.md").read_bytes()


@pytest.mark.slow
def test_a_capture_stays_on_one_side_and_mocap_splits_do_not_move(both: BuildReport, built_dir: Path) -> None:
    rows = _index(both.out)
    side: dict[str, str] = {}
    for r in rows:
        assert side.setdefault(r["take"], r["split"]) == r["split"], r["take"]
    hdm05_sides = {r["split"] for r in rows if r["source"] == "hdm05"}
    assert hdm05_sides == {"train", "val", "test"}  # HDM05 reaches every split
    alone = {r["id"]: r["split"] for r in _index(built_dir)}  # the mocap-only build (tests/conftest.py)
    assert {r["id"]: r["split"] for r in rows if r["id"] in alone} == alone
