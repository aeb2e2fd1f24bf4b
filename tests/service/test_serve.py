"""``riderlive serve``'s signals: a second Ctrl+C while it stops does not cut the stop short."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest

from tests.service.conftest import BASE_CONFIG
from tests.service.live_server import LiveServer
from tests.waiting import wait_until


def started(tmp_path: Path, inherited: signal.Handlers) -> LiveServer:
    """A server started with SIGINT's disposition ``inherited`` (this process's, while it forks)."""
    previous = signal.signal(signal.SIGINT, inherited)
    try:
        return LiveServer(BASE_CONFIG, tmp_path)
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("inherited", [signal.SIG_DFL, signal.SIG_IGN], ids=["default", "ignored"])
def test_a_second_ctrl_c_while_stopping_is_answered_and_the_take_is_closed(
    tmp_path: Path, inherited: signal.Handlers
) -> None:
    """uvicorn alone forces the exit at the second SIGINT: the app's shutdown is cancelled (a
    traceback, the take left incomplete, the park left to the guardian). Here the stop runs
    to its end and says why the press was not obeyed. The exit status is 130 (Ctrl+C) also
    for a server started with SIGINT ignored (a background job of a script; a test worker
    started in the background), where uvicorn's re-raise of the signal at the end did
    nothing and the status was 0."""
    live = started(tmp_path, inherited)
    try:
        live.request("POST", "/api/record/start", json={"name": "twice"})
        rows = lambda: live.get("/api/state").json()["recording"]["rows"]  # noqa: E731
        wait_until(lambda: rows() > 30, 15.0, rows)
        live.proc.send_signal(signal.SIGINT)
        # Python runs one handler for signals that arrive together: the second waits for the
        # stop to have begun (it parks, stops the tick and the guardian: hundreds of ms).
        wait_until(lambda: "Shutting down" in "".join(live.log), 10.0, poll=0.005)
        live.proc.send_signal(signal.SIGINT)
        code = live.proc.wait(30.0)  # (live.stop() would send a third SIGINT)
    finally:
        live.stop()
    log = "".join(live.log)
    assert code == 130, log[-2000:]  # Ctrl+C, after a clean shutdown
    assert "Ctrl+C once more abandons it" in log
    assert "Application shutdown complete" in log, log
    assert "Traceback" not in log and "stop abandoned" not in log, log[-2000:]
    meta = json.loads((tmp_path / "takes" / "twice.json").read_text())
    assert meta["complete"] is True  # the take was closed by the shutdown, not left for recovery
