"""Prompt files for ``physmotion generate --prompts FILE``: many prompts, one process, one batch.

The format, one prompt a line::

    # comments and blank lines are skipped
    a person walks forward
    a person jumps in place | 3.5
    a person waves the right hand<TAB>4

A line may end in its length in seconds after the last ``|`` or tab; without it the length is the
command's ``--seconds``, or where that is not given, predicted from the text (physmotion/text/length.py).
An explicit ``--seconds`` applies to every line (the CLI warns where it overrides a line's own seconds).
The file is UTF-8; errors name the file and the line. Nothing heavy is imported here: the command line
checks a prompt file before it imports torch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from physmotion.errors import PhysmotionError


@dataclass(frozen=True)
class Prompt:
    text: str
    seconds: float | None  # None: the command's --seconds, or predicted from the text
    line: int  # 1-based line in the file


def parse_prompts(text: str, name: str = "<prompts>") -> list[Prompt]:
    """The prompts of a prompt file's contents (see the module's docstring); ``name`` prefixes errors."""
    prompts = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        cut = max(line.rfind("|"), line.rfind("\t"))
        seconds = None
        if cut >= 0:
            given = line[cut + 1 :].strip()
            try:
                seconds = float(given)
            except ValueError:
                raise PhysmotionError(f"{name}:{number}: {given!r} after '|' (or a tab) is not a length in "
                                      "seconds; write 'a prompt | 3.5', or leave the length out") from None  # fmt: skip
            if not math.isfinite(seconds):
                raise PhysmotionError(
                    f"{name}:{number}: the length must be a finite number of seconds, got {given}"
                )
            line = line[:cut].strip()
            if not line:
                raise PhysmotionError(f"{name}:{number}: no prompt before the length {given}")
        prompts.append(Prompt(line, seconds, number))
    if not prompts:
        raise PhysmotionError(f"{name}: no prompts (one a line; blank lines and # comments are skipped)")
    return prompts


def read_prompts(path: str | Path) -> list[Prompt]:
    """The prompts of a UTF-8 prompt file; a missing, unreadable or empty file is a PhysmotionError."""
    path = Path(path)
    try:
        data = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise PhysmotionError(f"{path}: no such prompt file") from None
    except UnicodeDecodeError as exc:
        line = path.read_bytes()[: exc.start].count(b"\n") + 1
        raise PhysmotionError(f"{path}:{line}: not UTF-8 text") from None
    except OSError as exc:
        raise PhysmotionError(f"{path}: cannot read the prompt file ({exc.strerror or exc})") from None
    return parse_prompts(data, str(path))


def check_seconds(prompts: list[Prompt], lo: float, hi: float, name: str) -> None:
    """Refuse a line whose own length is outside the model's range [lo, hi] seconds, naming its line."""
    for p in prompts:
        if p.seconds is not None and not lo <= p.seconds <= hi:
            raise PhysmotionError(f"{name}:{p.line}: the length must be between {lo:g} and {hi:g} seconds (the "
                                  f"model's range), got {p.seconds:g}")  # fmt: skip
