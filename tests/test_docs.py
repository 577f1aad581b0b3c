"""The docs stay what they promise: a short README, a CLI reference that names every command and option,
and decision records whose pointers, index and statuses agree. (Figures are checked in test_results.py.)"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import typer

from physmotion.cli import app

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
CLI_DOC = ROOT / "docs" / "cli.md"
DECISIONS = ROOT / "docs" / "decisions"
ENTRY = re.compile(r"^## (\d{4}-\d\d-\d\d): (.+)$", re.M)


def test_readme_is_short_and_undated() -> None:
    lines = README.read_text().splitlines()
    assert len(lines) <= 150, f"README.md has {len(lines)} lines; the rest belongs in docs/"
    dated = [line for line in lines if re.search(r"\b20\d\d-\d\d-\d\d\b", line)]
    assert not dated, f"README.md lines carry dates: {dated}"


def test_readme_names_the_two_commands_and_the_path() -> None:
    text = README.read_text()
    for needed in ("make demo", "make test", "source .venv/bin/activate", ".ci/run"):
        assert needed in text, f"README.md does not say {needed!r}"
    assert "make test" in (ROOT / ".ci" / "run").read_text()


def _commands(command, path=()):  # (("data", "build"), click command), ...
    if hasattr(command, "commands"):
        for name, sub in command.commands.items():
            yield from _commands(sub, (*path, name))
    else:
        yield path, command


COMMANDS = list(_commands(typer.main.get_command(app)))


@pytest.mark.parametrize(("path", "command"), COMMANDS, ids=[" ".join(p) for p, _ in COMMANDS])
def test_cli_doc_names_every_command_and_option(path: tuple[str, ...], command) -> None:
    sections = re.split(r"(?m)^## ", CLI_DOC.read_text())
    section = next((s for s in sections if s.split("\n", 1)[0].strip() == " ".join(path)), None)
    assert section is not None, f"docs/cli.md has no '## {' '.join(path)}' section"
    flags = [opt for param in command.params if not getattr(param, "hidden", False)
             for opt in (*param.opts, *getattr(param, "secondary_opts", ())) if opt.startswith("--")]
    missing = [flag for flag in flags if flag != "--help" and f"`{flag}`" not in section]
    assert not missing, f"docs/cli.md's '{' '.join(path)}' section does not name {missing}"


def _entries() -> dict[str, list[tuple[str, str, str]]]:
    """Topic file -> its entries as (date, title, status)."""
    found = {}
    for path in sorted(DECISIONS.glob("*.md")):
        if path.name == "README.md":
            continue
        parts = re.split(r"(?m)^(?=## \d{4}-\d\d-\d\d: )", path.read_text())[1:]
        rows = []
        for part in parts:
            date, title = ENTRY.match(part).groups()
            status = re.match(r"\n\*\*(current|superseded)\*\*", part.split("\n", 1)[1])
            assert status, f"{path.name}: entry {title!r} has no **current** or **superseded** line under it"
            rows.append((date, title, status.group(1)))
        found[path.stem] = rows
    return found


def test_decisions_index_lists_every_entry_with_its_status() -> None:
    index = (DECISIONS / "README.md").read_text()
    row = r"^\| (\d{4}-\d\d-\d\d) \| (.+?) \| \[(\w+)\]\(\w+\.md\) \| (\w+) \|$"
    listed = set(re.findall(row, index, re.M))
    entries = {(d, t, topic, s) for topic, rows in _entries().items() for d, t, s in rows}
    assert entries == listed, f"index only: {listed - entries}; files only: {entries - listed}"


def test_superseded_entries_name_an_existing_entry() -> None:
    titles = {t for rows in _entries().values() for _, t, _ in rows}
    for path in DECISIONS.glob("*.md"):
        for line in re.findall(r"^\*\*superseded\*\* by \"([^\"]+)\"", path.read_text(), re.M):
            assert any(t.startswith(line) for t in titles), f"{path.name}: superseded by unknown {line!r}"


POINTER = re.compile(r"decisions(?:/(\w+))?\.md[:,]?\s*(?:#\s*)?\(?\"([^\"\n]+)")


def _pointer_files() -> list[Path]:
    files = [p for top in ("physmotion", "experiments", "tests", "docs", "results")
             for p in (ROOT / top).rglob("*") if p.suffix in {".py", ".md"} and p.is_file()]
    here = Path(__file__).resolve()
    return [p for p in files + [README, ROOT / "Makefile"]
            if p.exists() and DECISIONS not in p.parents and p.resolve() != here]


def test_pointers_name_a_topic_file_and_an_entry_in_it() -> None:
    """`docs/decisions/<topic>.md "title"` in code and docs names an entry of that file (a title cut at
    the end of a line is matched as a prefix); the old single file is gone."""
    entries = _entries()
    bad = []
    for path in _pointer_files():
        text = path.read_text()
        if "docs/decisions.md" in text:
            bad.append(f"{path.relative_to(ROOT)}: docs/decisions.md (now docs/decisions/<topic>.md)")
        for topic, title in POINTER.findall(text):
            titles = [t.replace("`", "") for _, t, _ in entries.get(topic, [])]
            if not any(t.startswith(title.replace("`", "")) for t in titles):
                where = f"decisions/{topic}.md" if topic else "decisions.md"
                bad.append(f"{path.relative_to(ROOT)}: {where} \"{title}\"")
    assert not bad, "pointers to no decision entry:\n" + "\n".join(bad)
