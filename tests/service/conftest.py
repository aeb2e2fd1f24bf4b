from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from tests.service.live_server import LiveServer
from tests.service.rig_server import serve_rig

BASE_CONFIG = """
[tick]
rate = 200.0
realtime_priority = false
preset_dirs = ["presets"]
hang_floor = 1.0  # the shared test server is not about supervision: no false restarts under load
spare = false  # nor about failover: one process (~1.6 s of CPU, more loaded) less per start; see SPARE_CONFIG

[input]
delay = 0.03
hold = 0.5
ease_time = 0.4
blend_time = 0.0
producer_timeout = 0.3

[source]
resume_after = 0.5

[publish]
send_timeout = 0.5
"""

SPARE_CONFIG = BASE_CONFIG.replace("spare = false", "spare = true")
"""BASE_CONFIG with the warm spare (the default of ``tick.spare``): for tests of a failover."""
assert SPARE_CONFIG != BASE_CONFIG


@pytest.fixture(scope="package")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One default server for tests/service, stopped when the package ends: an idle server
    costs ~0.55 of a core (tick at 200 Hz with its 1 ms spin 0.38, web 0.17), which a
    session scope charged to every test after tests/service (tests/web's software WebGL
    pages ran 2-3x slower in the full suite than alone)."""
    live = LiveServer(BASE_CONFIG, tmp_path_factory.mktemp("serve"))
    yield live
    live.stop()


@pytest.fixture(scope="package")
def shared_rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """bench3 on the emulated bus, no spare (:func:`tests.service.rig_server.serve_rig`): one
    server for the tests that read its start or arm it once and measure (``test_hostcheck``,
    ``test_latency``); a test that arms it disarms it again (the rig then ``parked``)."""
    with serve_rig(tmp_path_factory.mktemp("rig"), spare=False) as live:
        yield live


_FAILED_LOGS: dict[str, list[str]] = {}
"""The server logs of failed tests (by test id), printed at the end of the run."""


def _state_line(live: LiveServer) -> str:
    try:
        state = live.get("/api/state", timeout=2.0, headers=live.auth).json()
    except (httpx.HTTPError, ValueError) as exc:
        return f"/api/state: {exc}"
    return f"/api/state supervision: {state.get('supervision')}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    """A failed test against a live server gets its server's supervision and log tail: a
    tick that went down in CI is otherwise a bare timeout."""
    outcome: Any = yield
    report = outcome.get_result()
    if not report.failed:
        return
    for value in getattr(item, "funcargs", {}).values():
        if isinstance(value, LiveServer):
            tail = [_state_line(value), *value.log[-40:]]
            report.sections.append(("riderlive serve", "\n".join(line.rstrip() for line in tail)))
            _FAILED_LOGS.setdefault(item.nodeid, tail)


def pytest_terminal_summary(terminalreporter: Any) -> None:
    for nodeid, tail in list(_FAILED_LOGS.items())[:3]:
        terminalreporter.write_sep("-", f"riderlive serve behind {nodeid}")
        for line in tail:
            terminalreporter.write_line(line.rstrip())


@pytest.fixture
def receivers() -> Iterator[tuple[Any, Any]]:
    """A rider and a horse VMC receiver (python-osc servers on loopback UDP), closed after."""
    pytest.importorskip("pythonosc")
    from tests.vmc.receiver import VmcReceiver

    rider, horse = VmcReceiver(), VmcReceiver()
    yield rider, horse
    rider.close()
    horse.close()
