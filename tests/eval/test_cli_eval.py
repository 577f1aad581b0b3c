"""`physmotion evaluate` and `physmotion train evaluator` as a user runs them."""

import json

from tests.test_cli import run


def test_evaluate_quick_writes_markdown_and_json(tiny_model_dir, tiny_evaluator_dir, built_dir, tmp_path):
    out = tmp_path / "res" / "quick"
    res = run("evaluate", "--data", built_dir, "--model", tiny_model_dir, "--evaluator", tiny_evaluator_dir,
              "--physics", "none,post:1", "--no-recover", "--quick", "--eta", "1", "-o", out)
    assert res.returncode == 0, res.stderr
    assert "| real |" in res.stdout and "| post:1 |" in res.stdout
    data = json.loads(out.with_suffix(".json").read_text())
    assert set(data["rows"]) == {"real", "none", "post:1"} and data["meta"]["motions"] == 32
    assert data["meta"]["sampler"]["eta"] == 1.0 and data["meta"]["sampler"]["steps"] == 10
    assert sorted(p.name for p in out.parent.iterdir()) == ["quick.json", "quick.md"]  # quick.parts removed
    # A run killed before its table: the same command resumes from its saved runs and says so.
    parts = out.parent / "quick.parts"
    parts.mkdir()
    (parts / "none_r0.npz").write_bytes(b"cut short")  # unreadable: computed again, not reused
    res = run("evaluate", "--data", built_dir, "--model", tiny_model_dir, "--evaluator", tiny_evaluator_dir,
              "--physics", "none", "--quick", "--eta", "1", "-o", out, "--overwrite")
    assert res.returncode == 0, res.stderr
    assert "quick.parts: 1 finished run(s) of an earlier evaluation" in res.stderr
    again = json.loads(out.with_suffix(".json").read_text())["rows"]["none"]
    assert again["FID"] == data["rows"]["none"]["FID"] and not parts.exists()


def test_evaluate_bad_input_is_one_line(tiny_model_dir, tiny_evaluator_dir, built_dir, tmp_path):
    cases = [
        ("--physics", "none,walk"),
        ("--physics", "physdiff:end:99,space:1"),
        ("--split", "nosuch"),
        ("--eta", "2"),
        ("--sampler", "euler"),
    ]
    for flag, value in cases:
        out = tmp_path / "bad"
        res = run("evaluate", "--data", built_dir, "--model", tiny_model_dir, "--evaluator", tiny_evaluator_dir,
                  flag, value, "--quick", "-o", out)
        assert res.returncode == 1, (flag, value, res.stderr)
        assert res.stderr.startswith("error: ") and res.stderr.strip().count("\n") == 0, res.stderr
        assert not out.with_suffix(".md").exists() and not out.with_suffix(".json").exists()
    res = run("evaluate", "--data", built_dir, "--evaluator", tmp_path / "no_evaluator", "--quick")
    assert res.returncode == 1 and "no model checkpoint" in res.stderr


def test_train_evaluator_one_epoch(built_dir, tmp_path):
    out = tmp_path / "ev"
    res = run("train", "evaluator", "--data", built_dir, "--out", out, "--epochs", "1", "--latent-dim", "16")
    assert res.returncode == 0, res.stderr
    assert "test R@1" in res.stdout and (out / "model.safetensors").is_file()
    again = run("train", "evaluator", "--data", built_dir, "--out", out, "--epochs", "1")
    assert again.returncode == 1 and "is a folder that is not empty" in again.stderr
