"""A killed test run leaves no process behind (tests/children.py): a pytest that started a
real ``riderlive serve`` (web process and what it spawned) is killed with SIGTERM, and
with SIGKILL; within a bound, neither the server nor any process of that run is left."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.children import MARKER, marked
from tests.service.live_server import ROOT
from tests.waiting import wait_until

HOLDER = """
import time
from tests.service.conftest import BASE_CONFIG
from tests.service.live_server import LiveServer

def test_hold(tmp_path):
    server = LiveServer(BASE_CONFIG, tmp_path, wait_for_ticks=False)  # its tick process: spawned
    print("SERVING", server.proc.pid, flush=True)
    time.sleep(600)  # the stimulus: the run is killed while it holds the server
"""


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _parent(pid: int) -> int:
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
    except (OSError, ValueError):
        return 0


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_a_killed_run_leaves_no_server(tmp_path: Path, sig: signal.Signals) -> None:
    holder = tmp_path / "test_holder.py"
    holder.write_text(HOLDER)
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    env.pop(MARKER, None)
    run = subprocess.Popen(
        [sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider", "-p", "tests.conftest", str(holder)],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        assert run.stdout is not None
        seen = []
        for line in run.stdout:  # until the web process answers (or the run ends)
            seen.append(line)
            if line.startswith("SERVING"):
                break
        assert seen and seen[-1].startswith("SERVING"), "".join(seen)
        serve = int(seen[-1].split()[1])
        family: list[int] = []

        def spawned() -> bool:  # the web process and what it started (its tick process)
            family[:] = marked(str(run.pid))
            return serve in family and any(_parent(pid) == serve for pid in family)

        wait_until(spawned, 120, lambda: family, poll=0.1)
        run.send_signal(sig)
        run.wait(60)
        wait_until(lambda: not any(_alive(pid) for pid in family), 60, lambda: [p for p in family if _alive(p)])
        assert marked(str(run.pid)) == []
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(10)


def test_a_workers_children_are_the_controllers_too(tmp_path: Path) -> None:
    """An xdist worker's run is ``<controller's run>/<worker pid>``: the controller's sweep
    finds what a killed worker left (its own sweep never ran), a run with another pid does not."""
    run = f"test-{os.getpid()}"
    env = dict(os.environ, **{MARKER: f"{run}/12345"})
    left = subprocess.Popen(["sleep", "60"], env=env)
    try:
        wait_until(lambda: left.pid in marked(run), 10, "the worker's child is not the controller's")
        assert left.pid not in marked(run + "0") and left.pid in marked(f"{run}/12345")
    finally:
        left.kill()
        left.wait(5)
