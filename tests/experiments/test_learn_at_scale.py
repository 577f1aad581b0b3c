"""experiments/learn_at_scale.py: the references interleave both kinds and share segments; labelling writes
chunks a fit can read, a second machine's share of the work keeps its global reference numbers, and a re-run
goes on where the last stopped."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from experiments.learn_at_scale import load_pairs, load_refs, main
from experiments.teacher_data import EVAL_PROMPTS
from physmotion.physics.policy import NUM_ACTIONS, OBS_DIM


@pytest.mark.slow
def test_references_then_labels_on_two_machines(small_built_dir: Path, tmp_path: Path) -> None:
    refs = tmp_path / "refs.npz"
    main(["refs", "--data", str(small_built_dir), "--captured", "2", "--motions", "1", "--out", str(refs),
          "--allow-dirty"])  # fmt: skip
    got = load_refs(refs)
    # 2 captured jobs, then the one generated motion's plain and pushed starts, interleaved
    assert [r["origin"] for r in got] == ["captured", "generated", "captured", "generated"]
    gen = [r for r in got if r["origin"] == "generated"]
    assert np.array_equal(gen[0]["joints"], gen[1]["joints"])  # one segment, two starts
    assert sum(bool(r["push"].any()) for r in gen) == 1
    assert all(r["joints"].shape[1:] == (22, 3) and r["fps"] > 0 and r["licence_tag"] for r in got)
    with np.load(refs) as z:
        assert not set(z["prompts"].tolist()) & EVAL_PROMPTS

    # two "machines" split the references: 0 on one, 3 on the other
    for start, folder in ((0, "a"), (3, "b")):
        main(["label", "--refs", str(refs), "--pairs", str(tmp_path / folder), "--start", str(start), "--limit", "1",
              "--workers", "1", "--allow-dirty"])  # fmt: skip
    index = json.loads((tmp_path / "b" / "index.json").read_text())
    assert [d["ref"] for d in index["done"].values()] == [3] and index["workers"] == 1
    # resumable: a re-run over a range partly written labels only what is new (reference 2), in a new chunk
    main(["label", "--refs", str(refs), "--pairs", str(tmp_path / "b"), "--start", "2", "--limit", "2",
          "--workers", "1", "--minutes", "0.01", "--allow-dirty"])  # fmt: skip
    index = json.loads((tmp_path / "b" / "index.json").read_text())
    assert sorted(d["ref"] for d in index["done"].values()) == [2, 3]
    assert len(list((tmp_path / "b").glob("pairs_*.npz"))) == 2
    x, y, ref = load_pairs([str(tmp_path / "a"), str(tmp_path / "b")])
    assert x.shape[1:] == (OBS_DIM,) and y.shape[1:] == (NUM_ACTIONS,) and len(x) == len(y) == len(ref)
    assert set(ref.tolist()) == {0, 2, 3} and np.all(np.abs(y) <= 1.0) and np.isfinite(x).all()
    done = json.loads((tmp_path / "a" / "index.json").read_text())["done"]
    assert sum(d["pairs"] for d in done.values()) == int((ref == 0).sum()) > 0
