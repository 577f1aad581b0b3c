"""experiments/model_vocabulary.py rebuilds the shipped base model's vocabulary.txt from its training build."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_model_vocabulary_script_rebuilds_the_file(built_all_dir: Path, tmp_path: Path) -> None:
    from physmotion.diffusion.model import BASE_MODEL_DIR

    (tmp_path / "config.json").write_text((BASE_MODEL_DIR / "config.json").read_text())
    script = [sys.executable, "-m", "experiments.model_vocabulary"]
    res = subprocess.run([*script, "--data", built_all_dir, "--model", tmp_path], cwd=ROOT, capture_output=True,
                         text=True, timeout=300, check=False)  # fmt: skip
    assert res.returncode == 0, res.stderr
    words = [w for w in (tmp_path / "vocabulary.txt").read_text().splitlines() if not w.startswith("#")]
    shipped = [w for w in (BASE_MODEL_DIR / "vocabulary.txt").read_text().splitlines() if not w.startswith("#")]
    assert words == shipped
    # the wrong length filter describes another set of motions than the model's: refused
    res = subprocess.run([*script, "--data", built_all_dir, "--model", tmp_path, "--max-frames", "120"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300, check=False)  # fmt: skip
    trained_on = json.loads((BASE_MODEL_DIR / "config.json").read_text())["info"]["train_items"]
    assert res.returncode == 1 and f"trained on {trained_on}" in res.stderr
