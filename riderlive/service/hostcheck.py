"""What an installation with a serial device needs from its host, checked at start.

A servo reply travels through the adapter (an FTDI's latency timer holds bytes up to
16 ms by default), then the kernel's tty worker (a normal-priority kernel thread, on a
USB adapter as on a pty) before the tick sees it. The tick runs at SCHED_FIFO, but that
worker competes with every other process, and on a virtual machine the hypervisor can
take a whole vCPU away (steal). Measured (``bench/probe_stall.py``, docs/hardware.md "A
busy host"): with both cores loaded by normal-priority work a reply's serial path was
up to 60 ms late; with that work kept off the tick's core, 7.6-23.5 ms at most. Raising
the tty worker itself (``[host] kernel_workers_priority``, service/kworkers.py) is the
fix that needs no CPU of its own (docs/performance.md "Kernel workers").

:func:`gather` reads the facts (the only I/O); :func:`advise` is pure: each
:class:`Advice` names the problem and the fix. ``serve`` prints them when a device is
configured.
"""

from __future__ import annotations

import enum
import os
import resource
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from riderlive.devices.registry import DeviceSpec

ISOLATED = Path("/sys/devices/system/cpu/isolated")
PROC_STAT = Path("/proc/stat")
TICK_PRIORITY = 50
"""The tick's SCHED_FIFO priority (realtime/pacing.py)."""
CAP_SYS_NICE = 23
STEAL_WARN_SHARE = 0.001
"""Steal above this share of CPU time since boot: a host that takes the CPUs away."""


class HostIssue(enum.Enum):
    LATENCY_TIMER = "latency_timer"
    NO_REALTIME = "no_realtime"
    REALTIME_OFF = "realtime_off"
    SHARED_CORES = "shared_cores"
    WEB_PRIORITY = "web_priority"
    STEAL = "steal"
    KERNEL_WORKERS = "kernel_workers"


@dataclass(frozen=True)
class HostFacts:
    cpus: int
    isolated: str
    """The kernel's isolated CPUs (``isolcpus=``), e.g. ``"1"``; empty: none."""
    realtime_allowed: bool
    """SCHED_FIFO at the tick's priority is permitted (root, or RLIMIT_RTPRIO)."""
    latency_timers_ms: Mapping[str, int | None]
    """Each device port's FTDI latency timer (ms; None: not an FTDI adapter)."""
    steal_share: float
    """CPU time stolen by the hypervisor since boot, as a share of all CPU time."""
    normal_kernel_workers: int = 0
    """Unbound kernel workers (``kworker/u*``, the tty flip buffer's) at normal scheduling now."""
    sys_nice: bool = True
    """This process may change other processes' scheduling (CAP_SYS_NICE, e.g. root)."""


@dataclass(frozen=True)
class Advice:
    issue: HostIssue
    message: str
    fix: str

    def __str__(self) -> str:
        return f"{self.message}; fix: {self.fix}"


def advise(facts: HostFacts, tick_realtime: bool, web_priority: int, kernel_workers_priority: int = 0) -> list[Advice]:
    """What this host should change for its serial devices (empty: nothing found);
    ``kernel_workers_priority``: ``host.kernel_workers_priority`` (0: off)."""
    out = []
    for port, timer in sorted(facts.latency_timers_ms.items()):
        if timer is not None and timer > 1:
            name = os.path.basename(port)
            out.append(
                Advice(
                    HostIssue.LATENCY_TIMER,
                    f"{port}: the FTDI latency timer is {timer} ms: every reply waits up to that long",
                    f"echo 1 > /sys/bus/usb-serial/devices/{name}/latency_timer (or `setserial {port} low_latency`; "
                    'persist with a udev rule: ATTR{latency_timer}="1")',
                )
            )
    if not tick_realtime:
        out.append(
            Advice(
                HostIssue.REALTIME_OFF,
                "tick.realtime_priority is off: the tick driving the devices runs at normal priority",
                "set tick.realtime_priority = true",
            )
        )
    elif not facts.realtime_allowed:
        out.append(
            Advice(
                HostIssue.NO_REALTIME,
                f"SCHED_FIFO {TICK_PRIORITY} is not permitted: the tick will run at normal priority",
                "run as root, or grant it: LimitRTPRIO=60 (systemd) or `@riderlive - rtprio 60` "
                "in /etc/security/limits.conf",
            )
        )
    if facts.cpus <= 2 and not facts.isolated:
        out.append(
            Advice(
                HostIssue.SHARED_CORES,
                f"{facts.cpus} CPUs shared with everything else: the tick, the web process and the kernel's tty "
                "worker that carries the servo replies compete with it (that worker, at normal priority, was "
                "measured up to 60 ms late with both cores busy; a hypervisor's steal stops all of them)",
                "keep other heavy work (render engine, browser) off one core, e.g. systemd AllowedCPUs= or "
                "`taskset -c 1`, or run it at a lower weight (nice 10, CPUWeight=20); or boot with isolcpus",
            )
        )
    if web_priority == 0 and (facts.cpus <= 2 and not facts.isolated):
        out.append(
            Advice(
                HostIssue.WEB_PRIORITY,
                "the web process (REST e-stops) runs at normal priority on a shared host",
                "set server.realtime_priority = 10 (SCHED_FIFO below the tick's 50)",
            )
        )
    if facts.normal_kernel_workers and not kernel_workers_priority:
        out.append(
            Advice(
                HostIssue.KERNEL_WORKERS,
                f"{facts.normal_kernel_workers} unbound kernel workers (kworker/u*, which carry the servo bytes "
                "through the tty layer) run at normal priority: with both cores busy a transfer waited up to "
                '4 ms for one (docs/performance.md "Kernel workers")',
                "set [host] kernel_workers_priority = 1 (as root), or `riderlive host tune --kernel-workers 1` "
                "from a systemd unit",
            )
        )
    elif kernel_workers_priority and not facts.sys_nice:
        out.append(
            Advice(
                HostIssue.KERNEL_WORKERS,
                "host.kernel_workers_priority is set but this user may not change kernel threads' scheduling",
                "run as root (CAP_SYS_NICE), or raise them from a root unit: `riderlive host tune --kernel-workers 1`",
            )
        )
    if facts.steal_share > STEAL_WARN_SHARE:
        out.append(
            Advice(
                HostIssue.STEAL,
                f"the hypervisor took {facts.steal_share:.1%} of CPU time since boot (steal): whole-machine "
                "stalls of ~100 ms; servo budgets ride through them (stall_ridethroughs), the motion does not, "
                "and a servo Bus Watchdog of 100 ms or less (rig bus_watchdog_ms) trips in one: the servos stop "
                "themselves, a fault (soak: 3 in 10 min with both cores busy)",
                "give the virtual machine dedicated (pinned) CPUs, or run on bare metal; else accept those faults, "
                "or raise bus_watchdog_ms to 160 (the servos then hold a dead host's last goal 60 ms longer)",
            )
        )
    return out


def parse_steal_share(text: str) -> float:
    """Steal / all CPU time from the ``cpu`` line of a ``/proc/stat`` text (0 if absent)."""
    for line in text.splitlines():
        fields = line.split()
        if fields and fields[0] == "cpu":
            values = [int(v) for v in fields[1:]]
            total = sum(values[:8])  # guest time is already in user/nice
            return values[7] / total if len(values) >= 8 and total else 0.0
    return 0.0


def device_ports(specs: Iterable[DeviceSpec]) -> list[str]:
    """The serial port of each configured device (a rig's from its map when not overridden)."""
    ports = []
    for spec in specs:
        port = spec.port
        if port is None and spec.kind == "dynamixel":
            from riderlive.dynamixel.rig import load_rig

            port = load_rig(spec.file).bus.port
        if port is not None:
            ports.append(port)
    return ports


def gather(ports: Iterable[str]) -> HostFacts:
    """Read this host's facts for :func:`advise`."""
    from riderlive.dynamixel.sdkbus import usb_latency_timer_ms

    try:
        isolated = ISOLATED.read_text().strip()
    except OSError:
        isolated = ""
    try:
        steal = parse_steal_share(PROC_STAT.read_text())
    except OSError:
        steal = 0.0
    soft, _ = resource.getrlimit(resource.RLIMIT_RTPRIO)
    allowed = os.geteuid() == 0 or soft == resource.RLIM_INFINITY or soft >= TICK_PRIORITY
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    from riderlive.service.kworkers import normal_workers

    timers = {p: usb_latency_timer_ms(p) for p in ports}
    return HostFacts(cpus, isolated, allowed, timers, steal, normal_workers(), has_sys_nice())


def parse_has_capability(status: str, bit: int) -> bool:
    """Whether ``CapEff`` of a ``/proc/PID/status`` text has capability ``bit`` (False if absent)."""
    for line in status.splitlines():
        if line.startswith("CapEff:"):
            return bool(int(line.split()[1], 16) >> bit & 1)
    return False


def has_sys_nice() -> bool:
    """This process holds CAP_SYS_NICE (bit 23)."""
    try:
        return parse_has_capability(Path("/proc/self/status").read_text(), CAP_SYS_NICE)
    except OSError:
        return os.geteuid() == 0
