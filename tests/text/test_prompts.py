"""Prompt files of ``generate --prompts``: lines, optional seconds, comments, errors naming the line."""

from __future__ import annotations

import pytest

from physmotion.errors import PhysmotionError
from physmotion.text.prompts import Prompt, check_seconds, parse_prompts, read_prompts


def test_lines_seconds_comments_and_blanks() -> None:
    text = "# a comment\n\na person walks forward\n  a person jumps | 3.5  \na person waves\t4\n   # indented comment\n"
    assert parse_prompts(text) == [Prompt("a person walks forward", None, 3), Prompt("a person jumps", 3.5, 4),
                                   Prompt("a person waves", 4.0, 5)]  # fmt: skip


@pytest.mark.parametrize(("text", "match"), [
    ("walk\njump | fast\n", r"p.txt:2: 'fast' after '\|'"),
    ("walk\n | 3\n", r"p.txt:2: no prompt before the length 3"),
    ("walk | nan\n", r"p.txt:1: the length must be a finite"),
    ("# only a comment\n\n", r"p.txt: no prompts"),
])  # fmt: skip
def test_errors_name_file_and_line(tmp_path, text: str, match: str) -> None:
    path = tmp_path / "p.txt"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(PhysmotionError, match=match):
        read_prompts(path)


def test_file_errors(tmp_path) -> None:
    with pytest.raises(PhysmotionError, match="no such prompt file"):
        read_prompts(tmp_path / "missing.txt")
    (tmp_path / "bad.txt").write_bytes(b"walk\n\xff\xfe jump\n")
    with pytest.raises(PhysmotionError, match=r"bad.txt:2: not UTF-8"):
        read_prompts(tmp_path / "bad.txt")


def test_seconds_outside_the_range_name_the_line() -> None:
    prompts = parse_prompts("walk | 3\n\njump | 12\n")
    check_seconds(prompts[:1], 2.0, 9.8, "p.txt")
    with pytest.raises(
        PhysmotionError, match=r"p.txt:3: the length must be between 2 and 9.8 seconds .* got 12"
    ):
        check_seconds(prompts, 2.0, 9.8, "p.txt")
