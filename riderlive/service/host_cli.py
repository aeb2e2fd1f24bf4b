"""``riderlive host``: what this host needs for serial devices (``check``), and the kernel's
unbound workers raised for installers who prefer a systemd unit to ``[host]
kernel_workers_priority`` (``tune``; ``--watch`` keeps new workers raised, as ``serve`` does).

    riderlive host check [--port /dev/ttyUSB0 ...]
    riderlive host tune --kernel-workers 1 [--watch]
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from types import FrameType

from riderlive.service.hostcheck import advise, gather
from riderlive.service.kworkers import MAX_PRIORITY, RESCAN_S, KernelWorkers, WorkerStats, check_priority


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=("check", "tune"))
    parser.add_argument("--port", action="append", default=[], help="check: a device's serial port (repeatable)")
    parser.add_argument(
        "--kernel-workers",
        type=int,
        default=1,
        metavar="PRIORITY",
        help=f"tune: SCHED_FIFO priority 1..{MAX_PRIORITY} for the unbound kernel workers (default 1)",
    )
    parser.add_argument(
        "--watch",
        action="store_true",
        help=f"tune: scan again every {RESCAN_S:g} s until SIGTERM/SIGINT, then put the raised workers back",
    )


def _stop(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def _report(stats: WorkerStats) -> None:
    print(
        f"riderlive host: {stats.workers} unbound kernel workers, {stats.raised} raised to SCHED_FIFO "
        f"{stats.priority}, {stats.below} left below it{f' ({stats.last_error})' if stats.below else ''}",
        flush=True,
    )


def run(args: argparse.Namespace) -> int:
    if args.action == "check":
        advice = advise(gather(args.port), tick_realtime=True, web_priority=10)
        for a in advice:
            print(f"riderlive host: {a}")
        if not advice:
            print("riderlive host: nothing to change")
        return 1 if advice else 0
    try:
        workers = KernelWorkers(check_priority(args.kernel_workers))
    except ValueError as exc:
        print(f"riderlive host: --kernel-workers: {exc}", file=sys.stderr)
        return 2
    if not args.watch:
        stats = workers.scan()
        _report(stats)
        return 1 if stats.below else 0
    signal.signal(signal.SIGTERM, _stop)  # before the first raise: from here a SIGTERM puts back what was raised
    try:
        _report(workers.scan())
        while True:
            time.sleep(RESCAN_S)
            workers.scan()
    except KeyboardInterrupt:
        restored = workers.restore()
        print(f"riderlive host: {restored} workers back to normal scheduling; {workers.stats.status()}", flush=True)
    return 0
