"""A broker that is not there, or that never answers, is a one-line error and exit 2 in time.

The real CLI (``riderlive serve --nats`` and every ``riderlive stage`` action) against a
closed port and against a listening socket that accepts and never sends the NATS greeting.
Time is measured from process start, so it includes the interpreter and the imports: the
same command with a URL that nats-py rejects before any connect (port 99999: the same
imports and event loop, no network), started at the same moment, is the baseline, and the
budget is baseline + 25 % (load noise between the two) + 3 s (``nats.connect_timeout`` is
2 s by default). On a busy host the start-up alone takes seconds. The connect alone, in
process, is bounded without that noise (test_connect_itself_is_bounded).

Every stage action runs as a process against the mute broker (the connect's timeout, and
the exit after it); against the closed port the actions run in this process (the same
``cli.main``: exit 2, the one line, within the budget, without two Python start-ups per
action), and ``serve`` and a cluster of closed ports run as processes.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.bus.dead_brokers import BAD_URL, closed_port, mute_port, race_with_baseline
from tests.cli_main import run_main

BUDGET_S = 3.0
NOISE = 0.25
"""Two processes started together on a loaded host end their imports up to this apart."""

STAGE_ACTIONS = {
    "list": [],
    "estop": ["--by", "test"],
    "heartbeat": ["--duration", "1"],
    "record": ["--rig", "r1", "--take", "t1", "--seconds", "1"],
    "takes": [],
    "replay": ["--take", "t1", "--rig", "r1"],
    "export": ["--take", "t1", "--out", "out.csv"],
}


@pytest.fixture(scope="module")
def mute() -> Iterator[int]:
    """A port that accepts connections and never writes a byte."""
    with mute_port() as port:
        yield port


SERVE = ["serve", "--nats", "{url}", "--rig", "r1", "--port", "0"]


def stage(action: str) -> list[str]:
    return ["stage", "--nats", "{url}", "--stage", "A", action, *STAGE_ACTIONS[action]]


def assert_one_line_exit_2(code: int, stderr: str, url: str) -> list[str]:
    """Exit 2 and one line on stderr naming ``url``; the lines."""
    lines = stderr.splitlines()
    assert code == 2, lines
    assert len(lines) == 1, lines
    assert url in lines[0] and "no NATS server answers" in lines[0], lines
    return lines


def assert_fails_fast(command: list[str], url: str, cwd: Path) -> None:
    """``command`` (with ``{url}``) against url: exit 2, one line naming it, within the budget."""
    run, base = race_with_baseline(command, url, cwd)
    assert base.code == 2 and "invalid connect url" in base.stderr, base.stderr
    lines = assert_one_line_exit_2(run.code, run.stderr, url)
    wall_s, base_s = run.wall_s, base.wall_s
    budget = base_s * (1.0 + NOISE) + BUDGET_S
    assert wall_s < budget, f"{wall_s:.2f} s (start-up baseline {base_s:.2f} s, budget {budget:.2f} s): {lines}"


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["closed", "mute"])
def test_serve_nats_fails_fast(kind: str, mute: int, tmp_path: Path) -> None:
    url = f"nats://127.0.0.1:{closed_port() if kind == 'closed' else mute}"
    assert_fails_fast(SERVE, url, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("action", sorted(STAGE_ACTIONS))
def test_every_stage_action_fails_fast(action: str, mute: int, tmp_path: Path) -> None:
    assert_fails_fast(stage(action), f"nats://127.0.0.1:{mute}", tmp_path)


@pytest.mark.parametrize("action", sorted(STAGE_ACTIONS))
def test_every_stage_action_against_a_closed_port_in_process(
    action: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The refused connect of each action: exit 2 and the one line, within the budget alone
    (the action's imports done first by its baseline, the URL nats-py rejects)."""
    monkeypatch.chdir(tmp_path)  # export writes its --out here
    base = run_main(*(a.format(url=BAD_URL) for a in stage(action)))
    assert base.returncode == 2 and "invalid connect url" in base.stderr, base.stderr
    url = f"nats://127.0.0.1:{closed_port()}"
    start = time.perf_counter()
    done = run_main(*(a.format(url=url) for a in stage(action)))
    wall_s = time.perf_counter() - start
    assert_one_line_exit_2(done.returncode, done.stderr, url)
    assert wall_s < BUDGET_S, f"{wall_s:.2f} s"


@pytest.mark.slow
def test_a_cluster_of_dead_servers_is_one_error(tmp_path: Path) -> None:
    """Every server of a comma-separated URL is tried once, then the first error is told."""
    url = f"nats://127.0.0.1:{closed_port()},nats://127.0.0.1:{closed_port()}"
    assert_fails_fast(stage("list"), url, tmp_path)


@pytest.mark.parametrize("kind", ["closed", "mute"])
def test_connect_itself_is_bounded(kind: str, mute: int) -> None:
    """In process, without start-up noise: the first connect ends within connect_timeout."""
    from riderlive.bus.nats import connect
    from riderlive.bus.transport import Unreachable

    url = f"nats://127.0.0.1:{closed_port() if kind == 'closed' else mute}"
    start = time.perf_counter()
    with pytest.raises(Unreachable, match="no NATS server answers"):
        asyncio.run(connect(url, connect_timeout=0.5))
    assert time.perf_counter() - start < 0.5 + 0.5
