"""The ``physmotion`` command line: thin commands over the library's public functions.

One module per command group of ``physmotion --help``; each registers its commands on the one typer app
(``_common.app``) when imported. Any :class:`~physmotion.errors.PhysmotionError` becomes one line on
stderr and exit code 1 (:func:`main`).
"""

from __future__ import annotations

import sys

# The order of these imports is the order of ``physmotion --help``'s commands (typer lists them as
# registered: the commands, then the groups data, train, morph).
from physmotion.cli import io, physics, metrics, generate, evaluate, render, serve  # noqa: F401  # fmt: skip
from physmotion.cli import data, train, morph  # noqa: F401  # fmt: skip
from physmotion.cli._common import _warn, app
from physmotion.errors import PhysmotionError, PhysmotionWarning

__all__ = ["app", "main"]


def main() -> None:
    """Entry point of the console script: user errors become one line, never a traceback."""
    import warnings

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, PhysmotionWarning):
            _warn(str(message))
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show  # a library warning reads as one line, like an error
    try:
        app()
    except PhysmotionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(1) from None
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        raise SystemExit(130) from None
