"""Settings for the whole suite.

Hypothesis's per-example deadline (200 ms by default) measures the host, not the code: on
two shared cores under load an example that takes 5 ms quiet takes 400 ms, and the test
fails for it. Speed is measured in ``bench/``, so the suite's profile has no deadline."""

from __future__ import annotations

import atexit
import signal
import threading

import pytest
from hypothesis import settings

from tests import children

settings.register_profile("riderlive", deadline=None)
settings.load_profile("riderlive")


# Processes this run starts die with it (tests/children.py): the run's marker in the
# environment every child inherits, SIGTERM as KeyboardInterrupt (fixtures' finalizers
# stop their servers), and a sweep of whatever carries the marker at the end and at exit.
RUN = children.mark_run()
atexit.register(children.sweep, RUN)


def _interrupted(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


if threading.current_thread() is threading.main_thread():
    signal.signal(signal.SIGTERM, _interrupted)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    children.sweep(RUN)
