"""How a tick or spare process's Python code ended, for the log (the soak once saw a tick exit
255 with nothing said: ``SystemExit(-1)`` and an exec that failed before Python ran both look
like that; ``realtime/link.py`` names them)."""

from __future__ import annotations

import contextlib
import faulthandler
import logging
import os
from collections.abc import Iterator

log = logging.getLogger("riderlive.realtime.spare")


@contextlib.contextmanager
def last_words(who: str) -> Iterator[None]:
    """A tick or spare process's Python entry: say it started (a process that exits 255 without
    this line never ran Python: its exec failed), dump the stacks on a fatal signal
    (``faulthandler``), and log how its Python code ended when not by returning: the
    exception with its traceback, or ``SystemExit`` with its code (``SystemExit(-1)`` is
    ``exit 255``, silent otherwise). Nothing is logged for a normal end."""
    faulthandler.enable()
    log.info("%s started (pid %d)", who, os.getpid())
    try:
        yield
    except SystemExit as exc:
        if exc.code not in (None, 0):
            log.critical("%s (pid %d) ends by SystemExit(%r)", who, os.getpid(), exc.code, exc_info=True)
        raise
    except BaseException as exc:
        log.critical("%s (pid %d) ends by %s: %s", who, os.getpid(), type(exc).__name__, exc, exc_info=True)
        raise
