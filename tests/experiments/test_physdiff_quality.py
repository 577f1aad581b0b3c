"""experiments/physdiff_quality.py runs end to end in its own process and writes what it promises."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_physdiff_quality_writes_its_json(tmp_path: Path) -> None:
    # One prompt, one seed, every mode; --tau reaches the projection and the record.
    out = tmp_path / "pq"
    res = subprocess.run([sys.executable, "-m", "experiments.physdiff_quality", "--prompts", "1",
                          "--seeds", "0", "--tau", "0.25", "--out", str(out), "--allow-dirty"],
                         cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "reset at 0.25 m" in res.stdout and "reset at 0.25 m" in out.with_suffix(".md").read_text()
    data = json.loads(out.with_suffix(".json").read_text())
    assert data["meta"]["prompts"] == 1 and data["meta"]["tau"] == 0.25 and data["meta"]["seeds"] == [0]
    assert data["meta"]["preset"] == {"physdiff, post": "sampling", "morph": "plain"}
    (run,) = data["runs"]
    assert set(run) == {"none", "none+floor", "post:1", "post:4", "physdiff:end:4,space:1"}
    assert run["physdiff:end:4,space:1"]["phys_err"] < run["none"]["phys_err"]
    # P's modes record the outside help: the pelvis residual and the share of frames at its 0.3 W cap
    # and torque, and the frames with a joint over its torque limit (none: this preset balances by the root)
    for mode in ("post:1", "post:4", "physdiff:end:4,space:1"):
        assert 0 < run[mode]["residual_force"] <= 0.3 + 1e-6 and 0 <= run[mode]["residual_at_cap"] <= 1
        assert run[mode]["residual_torque_p95"] >= run[mode]["residual_torque"] > 0
        assert run[mode]["over_limit"] == 0.0
    assert "residual_force" not in run["none"]
    for column in ("root force W mean / p95 (at cap)", "root torque W m mean / p95", "torque over limit"):
        assert column in res.stdout
    # --runs-from joins runs made apart (the seeds in parallel processes) into one table and file; a run
    # with other settings is refused. The second part here is the first relabelled as seed 1.
    other = tmp_path / "seed1.json"
    other.write_text(json.dumps({**data, "meta": {**data["meta"], "seeds": [1]}}))
    joined = tmp_path / "joined"
    res = subprocess.run([sys.executable, "-m", "experiments.physdiff_quality", "--runs-from",
                          str(out.with_suffix(".json")), str(other), "--out", str(joined), "--allow-dirty"],
                         cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)  # fmt: skip
    assert res.returncode == 0, res.stderr
    both = json.loads(joined.with_suffix(".json").read_text())
    assert both["meta"]["seeds"] == [0, 1] and both["runs"] == [run, run] and len(both["meta"]["parts"]) == 2
    assert both["meta"]["tau"] == 0.25 and "mean over seeds 0,1" in joined.with_suffix(".md").read_text()
    other.write_text(json.dumps({**data, "meta": {**data["meta"], "seeds": [1], "tau": 0.15}}))
    res = subprocess.run([sys.executable, "-m", "experiments.physdiff_quality", "--runs-from",
                          str(out.with_suffix(".json")), str(other), "--out", str(joined), "--allow-dirty"],
                         cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)  # fmt: skip
    assert res.returncode != 0 and "not a physics-set run with the settings of" in res.stderr
