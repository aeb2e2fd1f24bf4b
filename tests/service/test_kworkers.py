"""The kernel's unbound workers raised to a low SCHED_FIFO priority: the pure policy (which
threads, to what), and the edge against real processes this test starts (named like a
worker for a test-only pattern, so the host's own kernel workers are never touched)."""

from __future__ import annotations

import asyncio
import os
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.service.kworkers import (
    MAX_PRIORITY,
    KernelWorkers,
    KThread,
    Sched,
    all_pids,
    census,
    check_priority,
    is_unbound_worker,
    keep_raised,
    kthreadd_children,
    normal_workers,
    read_sched,
    wanted,
)
from tests.children import popen
from tests.waiting import await_until, wait_until

ROOT = os.geteuid() == 0
NEEDS_ROOT = pytest.mark.skipif(not ROOT, reason="raising another process to SCHED_FIFO needs root (CAP_SYS_NICE)")


@pytest.mark.parametrize(
    ("comm", "expected"),
    [
        ("kworker/u8:2", True),
        ("kworker/u8:2-events_unbound", True),
        ("kworker/u9:0", True),
        ("kworker/u128:17-flush-8:0", True),
        ("kworker/0:1", False),  # per-CPU: bound to its CPU, not the tty's
        ("kworker/1:0H-events_highpri", False),
        ("kworker/R-rcu_gp", False),  # a rescuer
        ("kworker/u", False),
        ("xkworker/u8:2", False),
        ("ksoftirqd/0", False),
        ("python", False),
    ],
)
def test_only_unbound_workers_match(comm: str, expected: bool) -> None:
    assert is_unbound_worker(comm) is expected


POLICIES = st.sampled_from([int(p) for p in Sched] + [4, 7])


@given(
    comm=st.sampled_from(["kworker/u8:1", "kworker/u9:0-events_unbound", "kworker/0:2", "bash"]),
    policy=POLICIES,
    current=st.integers(0, 99),
    priority=st.integers(0, MAX_PRIORITY),
)
def test_the_policy_raises_exactly_the_matching_workers_below_the_priority(
    comm: str, policy: int, current: int, priority: int
) -> None:
    rt = policy in (Sched.FIFO, Sched.RR)
    thread = KThread(1234, comm, policy, current if rt else 0)
    result = wanted(thread, priority)
    if priority == 0 or not is_unbound_worker(comm):
        assert result is False  # off, or not a worker: never touched
    elif rt:
        assert result is (current < priority)  # never lowered, never re-set at its own priority
    else:
        assert result is (policy in (Sched.OTHER, Sched.BATCH, Sched.IDLE))  # DEADLINE and unknown left alone


@given(st.integers(-1000, 1000))
def test_priorities_are_off_or_below_the_web_process(priority: int) -> None:
    if 0 <= priority <= 9:
        assert check_priority(priority) == priority
    else:
        with pytest.raises(ValueError, match=r"0 \(off\) or 1\.\.9"):
            check_priority(priority)


def test_the_kernel_threads_are_listed_and_include_unbound_workers() -> None:
    kernel = kthreadd_children()
    assert kernel and set(kernel) <= set(all_pids())
    names = [(Path(f"/proc/{p}/comm").read_text().strip()) for p in kernel if Path(f"/proc/{p}/comm").exists()]
    assert any(is_unbound_worker(n) for n in names), names
    assert os.getpid() not in kernel


def test_the_census_counts_every_unbound_worker_by_its_scheduling() -> None:
    counts = census()
    assert sum(counts.values()) >= 1
    assert all(
        key == "normal" or (key.split()[0] in ("FIFO", "RR") and 1 <= int(key.split()[1]) <= 99) for key in counts
    )
    assert abs(normal_workers() - counts["normal"]) <= 2  # the same count (workers come and go meanwhile)


def test_without_the_children_file_every_pid_is_listed(tmp_path: Path) -> None:
    for pid in ("1", "2", "77"):
        (tmp_path / pid).mkdir()
    (tmp_path / "self").mkdir()
    assert sorted(kthreadd_children(tmp_path)) == [1, 2, 77]


FAKE = "rltestkw/"
"""The test's stand-in workers' name prefix (``prctl(PR_SET_NAME)``, 15 bytes at most)."""


def fake_worker(comm: str) -> bool:
    return comm.startswith(FAKE)


def named_child(name: str) -> tuple[int, object]:
    """A child process named ``name`` (its ``comm``) that lives until its stdin closes."""
    code = (
        "import ctypes,sys; ctypes.CDLL(None).prctl(15, ctypes.c_char_p(sys.argv[1].encode()), 0, 0, 0);"
        "print('ready', flush=True); sys.stdin.read()"
    )
    child = popen([sys.executable, "-c", code, name], stdin=-1, stdout=-1, text=True)
    assert child.stdout is not None and child.stdout.readline().strip() == "ready"
    assert Path(f"/proc/{child.pid}/comm").read_text().strip() == name
    return child.pid, child


def stop(child: object) -> None:
    child.stdin.close()  # type: ignore[attr-defined]
    child.wait(10)  # type: ignore[attr-defined]


@NEEDS_ROOT
def test_the_edge_raises_new_workers_leaves_higher_ones_and_restores_its_own() -> None:
    a_pid, a = named_child(FAKE + "u1:0")
    b_pid, b = named_child(FAKE + "u1:1")
    other_pid, other = named_child("rltest-other")
    try:
        os.sched_setscheduler(b_pid, Sched.FIFO, os.sched_param(30))  # someone raised it higher
        mine = [a_pid, b_pid, other_pid]
        workers = KernelWorkers(3, pids=lambda: mine, match=fake_worker)
        stats = workers.scan()
        assert (stats.workers, stats.below, stats.raised, dict(stats.failures)) == (2, 0, 1, {})
        assert read_sched(a_pid, "").policy == Sched.FIFO and read_sched(a_pid, "").priority == 3
        assert read_sched(b_pid, "").priority == 30  # never lowered
        assert read_sched(other_pid, "").policy == Sched.OTHER  # not a worker
        assert workers.scan().raised == 1  # already raised: nothing to do
        late_pid, late = named_child(FAKE + "u1:2")  # the kernel made a new worker
        mine.append(late_pid)
        assert workers.scan().raised == 2 and read_sched(late_pid, "").priority == 3
        os.sched_setscheduler(a_pid, Sched.OTHER, os.sched_param(0))  # someone put it back
        assert workers.scan().raised == 3 and read_sched(a_pid, "").priority == 3
        stop(late)
        assert workers.scan().workers == 2  # a worker that exits is forgotten
        assert workers.restore() == 1  # a only: b was never ours, late is gone
        assert read_sched(a_pid, "").policy == Sched.OTHER and read_sched(b_pid, "").priority == 30
        assert workers.stats.scans == 5 and workers.stats.scan_cpu_s > 0
    finally:
        for child in (a, b, other):
            stop(child)


def test_a_worker_that_cannot_be_raised_is_counted_with_its_errno(monkeypatch: pytest.MonkeyPatch) -> None:
    pid, child = named_child(FAKE + "u2:0")
    try:

        def refuse(*args: object) -> None:
            raise PermissionError(1, "Operation not permitted")

        monkeypatch.setattr(os, "sched_setscheduler", refuse)
        workers = KernelWorkers(1, pids=lambda: [pid, 999_999_999], match=fake_worker)
        stats = workers.scan()
        assert (stats.workers, stats.below, stats.raised, dict(stats.failures)) == (1, 1, 0, {"EPERM": 1})
        assert str(pid) in stats.last_error
        status = stats.status()
        assert status["below_priority"] == 1 and status["failures"] == {"EPERM": 1}
        text = stats.prometheus()
        assert 'riderlive_kernel_workers_failures_total{errno="EPERM"} 1' in text
        assert 'riderlive_kernel_workers{state="below"} 1' in text
    finally:
        stop(child)


@NEEDS_ROOT
def test_the_periodic_scan_keeps_raising_until_cancelled_then_restores() -> None:
    pid, child = named_child(FAKE + "u3:0")

    async def scenario() -> None:
        workers = KernelWorkers(2, pids=lambda: [pid], match=fake_worker)
        task = asyncio.create_task(keep_raised(workers, interval_s=0.01))
        await await_until(lambda: read_sched(pid, "").priority == 2, 5.0)
        os.sched_setscheduler(pid, Sched.OTHER, os.sched_param(0))
        await await_until(lambda: workers.stats.raised >= 2, 5.0)
        assert read_sched(pid, "").priority == 2
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        assert read_sched(pid, "").policy == Sched.OTHER

    try:
        asyncio.run(scenario())
    finally:
        stop(child)


def test_a_live_service_keeps_the_workers_raised_and_shows_it(tmp_path: Path) -> None:
    """``[host] kernel_workers_priority`` in a real ``serve``: ``/api/state``'s ``host``
    section and ``/metrics`` say what the scans did (as root: every worker at or above the
    priority; without root: each refusal counted as EPERM)."""
    from tests.service.conftest import BASE_CONFIG
    from tests.service.live_server import LiveServer

    live = LiveServer(BASE_CONFIG + "\n[host]\nkernel_workers_priority = 1\n", tmp_path)
    try:

        def section() -> dict[str, object]:
            return live.get("/api/state").json()["host"]["kernel_workers"]  # type: ignore[no-any-return]

        wait_until(lambda: section()["scans"] >= 2, 30.0, section)
        status = section()
        assert status["priority"] == 1 and isinstance(status["workers"], int) and status["workers"] >= 1
        if ROOT:
            assert status["below_priority"] == 0 and status["failures"] == {}
        else:
            assert status["below_priority"] == status["workers"] and "EPERM" in status["failures"]  # type: ignore[operator]
        metrics = live.get("/metrics").text
        assert "riderlive_kernel_workers_priority 1\n" in metrics
        assert "riderlive_kernel_workers_raised_total" in metrics
    finally:
        live.stop()


def test_without_the_key_the_state_says_off(server: object) -> None:
    assert server.get("/api/state").json()["host"] == {"kernel_workers": None}  # type: ignore[attr-defined]


def test_a_scan_that_raises_is_counted_and_the_next_one_runs() -> None:
    calls: list[int] = []

    def listing() -> list[int]:
        calls.append(len(calls))
        if len(calls) == 1:
            raise RuntimeError("proc went away")
        return []

    async def scenario() -> KernelWorkers:
        workers = KernelWorkers(1, pids=listing, match=fake_worker)
        task = asyncio.create_task(keep_raised(workers, interval_s=0.001))
        await await_until(lambda: workers.stats.scans >= 2, 5.0)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        return workers

    stats = asyncio.run(scenario()).stats
    assert stats.failures["RuntimeError"] == 1 and "proc went away" in stats.last_error
    assert stats.scans >= 2 and stats.workers == 0
