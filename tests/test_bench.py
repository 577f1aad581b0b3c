"""The benchmark scripts run end to end and write what they promise (their timings are not checked)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_physdiff_quality_writes_its_json(tmp_path: Path) -> None:
    # One prompt, one seed, every mode; --tau reaches the projection and the record.
    out = tmp_path / "pq.json"
    res = subprocess.run([sys.executable, str(ROOT / "bench" / "physdiff_quality.py"), "--prompts", "1",
                          "--seeds", "0", "--tau", "0.25", "--json", str(out)],
                         capture_output=True, text=True, timeout=600, check=False)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "reset at 0.25 m" in res.stdout
    data = json.loads(out.read_text())
    assert data["meta"]["prompts"] == 1 and data["meta"]["tau"] == 0.25 and data["meta"]["seeds"] == [0]
    (run,) = data["runs"]
    assert set(run) == {"none", "none+floor", "post:1", "post:4", "physdiff:end:4,space:1"}
    assert run["physdiff:end:4,space:1"]["phys_err"] < run["none"]["phys_err"]
