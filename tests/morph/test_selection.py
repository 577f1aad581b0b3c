"""Morph's imitation selection (Sec. 3.3) on hand-built index rows and folders."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from physmotion.errors import PhysmotionError
from physmotion.morph.selection import HELP_FIELDS, INDEX_FIELDS, read_synth_info, select, select_rows


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


def test_help_on_the_refined_items_over_their_frames(tmp_path: Path) -> None:
    """P's help is averaged over the refined items' frames; inputs kept do not count; an index made before
    the help columns (or a row without them) gives none."""
    rows = [row(0, 0.05) | {"frames": "60", "residual_force": "0.1", "residual_at_cap": "0.0", "over_limit": "0.5"},
            row(1, 0.05) | {"frames": "20", "residual_force": "0.2", "residual_at_cap": "1.0", "over_limit": "0.0"},
            row(2, 0.9) | {"frames": "60", "residual_force": "0.3", "residual_at_cap": "1.0", "over_limit": "1.0"}]
    sel = select_rows(rows, tmp_path)
    assert sel.help == pytest.approx({"residual_force": 0.125, "residual_at_cap": 0.25, "over_limit": 0.375})
    assert select_rows(ROWS, tmp_path).help == {}
    assert set(HELP_FIELDS) == set(sel.help)


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
    assert "P's help" not in res.output  # this index predates the help columns
    helped = [r | {"residual_force": "0.1", "residual_at_cap": "0.2", "over_limit": "0.0"} for r in ROWS]
    folder = tmp_path / "with_help"
    folder.mkdir()
    (folder / "synth.json").write_text("{}")
    fields = [*INDEX_FIELDS, *HELP_FIELDS]
    lines = [",".join(fields)] + [",".join(str(r[k]) for k in fields) for r in helped]
    (folder / "index.csv").write_text("\n".join(lines) + "\n")
    res = CliRunner().invoke(app, ["morph", "select", str(folder)])
    assert res.exit_code == 0, res.output
    assert "root residual force mean 0.100 W, at its cap in 20.0 % of frames" in res.output
