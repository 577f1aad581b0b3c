"""Morph's imitation selection (Sec. 3.3) on hand-built index rows and folders."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from physmotion.errors import PhysmotionError
from physmotion.morph.selection import INDEX_FIELDS, read_synth_info, select, select_rows


def row(i: int, mpjpe: float, success: int = 1, grounded: int = 1, caption: str = "a person walks") -> dict:
    return {"id": f"s{i:06d}", "caption": caption, "frames": "60", "mpjpe_mean": str(mpjpe),
            "mpjpe_max": str(mpjpe * 2), "success": str(success), "resets": "0", "grounded": str(grounded),
            "licence_tag": "NC"}  # fmt: skip


ROWS = [
    row(0, 0.05),  # refined
    row(1, 0.49),  # refined: just under tau
    row(2, 0.51),  # over tau: input
    row(3, 0.10, success=0),  # the humanoid fell: input
    row(4, 0.05, grounded=0, caption="a person sits on a chair"),  # non-grounded: input, not in IFR
    row(5, float("nan")),  # no measure: input
]


def test_selection_rule_and_ifr(tmp_path: Path) -> None:
    sel = select_rows(ROWS, tmp_path, tau=0.5)
    assert [s.source for s in sel.items] == ["refined", "refined", "input", "input", "input", "input"]
    assert sel.items[0].features_path == tmp_path / "new_joint_vecs" / "s000000.npy"
    assert sel.items[2].features_path == tmp_path / "input_joint_vecs" / "s000002.npy"
    assert sel.counts == {"items": 6, "refined": 2, "input": 4, "grounded": 5, "non_grounded": 1,
                          "failed": 3, "episode_failed": 1}  # fmt: skip
    assert sel.ifr == pytest.approx(3 / 5)
    assert sel.licence_tags == ["NC"]
    ids = [i for i, _, _ in sel.training_items()]
    assert ids == [f"s{i:06d}" for i in range(6)]


def test_tau_moves_the_cut(tmp_path: Path) -> None:
    assert select_rows(ROWS, tmp_path, tau=0.3).counts["refined"] == 1
    assert select_rows(ROWS, tmp_path, tau=1.0).counts["refined"] == 3


def write_folder(folder: Path, rows: list[dict]) -> Path:
    folder.mkdir()
    (folder / "synth.json").write_text(json.dumps({"licence_tags": ["NC", "open"], "model_sha256": "x"}))
    lines = [",".join(INDEX_FIELDS)] + [",".join(str(r[k]) for k in INDEX_FIELDS) for r in rows]
    (folder / "index.csv").write_text("\n".join(lines) + "\n")
    return folder


def test_select_on_a_folder(tmp_path: Path) -> None:
    folder = write_folder(tmp_path / "synth", ROWS)
    sel = select(folder)
    assert sel.counts["refined"] == 2 and sel.licence_tags == ["NC", "open"]
    assert read_synth_info(folder)["model_sha256"] == "x"


def test_empty_selection_is_one_line_error(tmp_path: Path) -> None:
    folder = write_folder(tmp_path / "synth", [])
    with pytest.raises(PhysmotionError, match="no finished synthetic item") as err:
        select(folder)
    assert "\n" not in str(err.value)
    with pytest.raises(PhysmotionError, match="empty") as err:
        select_rows([], tmp_path).training_items()
    assert "\n" not in str(err.value)


def test_not_a_synth_folder(tmp_path: Path) -> None:
    with pytest.raises(PhysmotionError, match="not a synthetic data folder"):
        select(tmp_path)


def test_cli_select(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from physmotion.cli import app

    folder = write_folder(tmp_path / "synth", ROWS)
    res = CliRunner().invoke(app, ["morph", "select", str(folder)])
    assert res.exit_code == 0, res.output
    assert "2 refined" in res.output and "IFR 0.600" in res.output and "non-grounded" in res.output
