"""``riderlive ARGS`` in the test's own process (the same ``cli.main``, no Python start)."""

from __future__ import annotations

import contextlib
import io
import subprocess


def run_main(*args: str) -> subprocess.CompletedProcess[str]:
    """``riderlive ARGS`` in this process: the same ``cli.main`` without a Python start and its
    imports per call (~2 s quiet, 15 s loaded); the exit code argparse raises is returned."""
    from riderlive.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(args))
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    return subprocess.CompletedProcess(list(args), code, out.getvalue(), err.getvalue())
