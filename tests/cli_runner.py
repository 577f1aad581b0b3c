"""The command line run in the test process: what a subprocess would give, without its start-up.

``invoke("generate", "walk", ...)`` calls :func:`physmotion.cli.main` as the console script does, with
``sys.argv`` set, stdout and stderr captured, and returns a :class:`subprocess.CompletedProcess` (exit
code, stdout, stderr), so a test reads the same either way. It runs ``main`` rather than typer's
``CliRunner.invoke(app, ...)`` because ``main`` is what turns a ``PhysmotionError`` into the one-line
``error: ...`` and a ``PhysmotionWarning`` into ``warning: ...``: the behaviour these tests check. An
unexpected exception becomes exit code 1 with its traceback on stderr, as in a real process.

A fresh interpreter costs 3-5 s (torch, the text encoder) per call; about 70 CLI calls made the suite
spend minutes starting Python. ``tests/test_cli_process.py`` (slow tier) runs a sample of the same
commands through the installed console script and checks that both give the same output.
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import traceback
import warnings
from pathlib import Path

PROG = "physmotion"


class _Text(io.StringIO):
    """A captured stream: not a terminal, like a pipe, so rich and the progress bars behave as in CI."""

    def isatty(self) -> bool:
        return False

    def fileno(self) -> int:
        raise io.UnsupportedOperation("captured stream")


def invoke(*args: object, cwd: str | Path | None = None) -> subprocess.CompletedProcess:
    """``physmotion ARGS...`` in this process; ``cwd`` runs it from another folder."""
    import physmotion.cli as cli

    argv = [PROG, *map(str, args)]
    out, err = _Text(), _Text()
    app = cli.app
    shown, old_argv, old_cwd = warnings.showwarning, sys.argv, os.getcwd()
    code: int = 0
    try:
        # The program name the usage lines print: "physmotion", whatever started pytest.
        cli.app = lambda: app(prog_name=PROG)  # type: ignore[assignment]
        sys.argv = argv
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
            warnings.simplefilter("default")  # a fresh registry per call: each warning shows, as in a new process
            try:
                cli.main()
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                if exc.code is not None and not isinstance(exc.code, int):
                    print(exc.code, file=sys.stderr)
            except BaseException:  # noqa: BLE001 - a real process prints the traceback and exits 1
                traceback.print_exc()
                code = 1
    finally:
        cli.app = app
        sys.argv = old_argv
        warnings.showwarning = shown
        os.chdir(old_cwd)
    return subprocess.CompletedProcess(argv, code, out.getvalue(), err.getvalue())
