"""What the rig benchmarks share: the timed emulator in a child process, a busy core.

The emulator (``tests.dynamixel.rig_harness.TimedBus``: it also notes every packet's
arrival) runs in its own process, so the SDK's busy-polling reads in the process under
test do not share a GIL with it. Ask it over a pipe:

    emu = Emulator(rig, baud=1_000_000, wire_timing=True)
    emu.ask("arrivals")        # [(perf_counter when fully arrived, raw packet), ...] since the last ask
    emu.ask(("torque", ids))   # Torque Enable of each id
    emu.ask(("fault", spec))   # apply an emulator FaultSpec; perf_counter when applied
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import re
import time
from collections.abc import Iterator
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from bench.serving import busy_cores
from riderlive.configfile import CONFIG_DIR
from riderlive.dynamixel.rig import RigConfig, load_rig
from riderlive.dynamixel.tables import Instruction, Item
from riderlive.sched import try_realtime_priority
from tests.dynamixel.rig_harness import TimedBus, is_torque_off_write, servo_setups

GOAL_POSITION = 116


def _serve(conn: Connection, rig: RigConfig, baud: int, wire_timing: bool, priority: int | None) -> None:
    if priority is not None:  # the emulator stands in for hardware, which is never late
        try_realtime_priority(priority)
    bus = TimedBus(servo_setups(rig), baud=baud, wire_timing=wire_timing).start()
    bus.arrivals = type(bus.arrivals)(maxlen=200_000)
    conn.send(bus.port)
    seen = 0
    while True:
        command = conn.recv()
        if command == "stop":
            bus.stop()
            conn.send(None)
            return
        bus.settle(timeout=30.0)
        if command == "arrivals":
            packets = list(bus.arrivals)
            conn.send(packets[seen - bus.stats.packets :] if seen < bus.stats.packets else [])
            seen = bus.stats.packets
        elif command == "stats":
            conn.send(dict(bus.stats.instructions))
        elif command == "bus_stats":
            conn.send({k: v for k, v in vars(bus.stats).items() if k != "instructions"})
        elif isinstance(command, tuple) and command[0] == "torque":
            conn.send([bus.read_item(i, Item.TORQUE_ENABLE) for i in command[1]])
        elif isinstance(command, tuple) and command[0] == "goal":
            conn.send([bus.read_item(i, Item.GOAL_POSITION) for i in command[1]])
        elif isinstance(command, tuple) and command[0] == "fault":  # ("fault", FaultSpec): apply now
            bus.apply(command[1])
            conn.send(time.perf_counter())


class Emulator:
    """The timed emulator in a child process (fork: it shares this process's imports)."""

    def __init__(
        self, rig: RigConfig, baud: int | None = None, wire_timing: bool = True, priority: int | None = None
    ) -> None:
        """``priority``: SCHED_FIFO for the emulator (where the system allows it)."""
        self.conn, child = mp.Pipe()
        context = mp.get_context("fork")
        args = (child, rig, baud or rig.bus.baud, wire_timing, priority)
        self.process = context.Process(target=_serve, args=args, daemon=True)
        self.process.start()
        self.port: str = self.conn.recv()

    def ask(self, command: Any) -> Any:
        self.conn.send(command)
        return self.conn.recv()

    def stop(self) -> None:
        with contextlib.suppress(OSError, EOFError):
            self.ask("stop")
        self.process.join(timeout=5)


def is_goal_write(raw: bytes) -> bool:
    return len(raw) > 9 and raw[7] == Instruction.SYNC_WRITE and raw[8] | raw[9] << 8 == GOAL_POSITION


def torque_offs(packets: list[tuple[float, bytes]]) -> list[float]:
    return [t for t, raw in packets if is_torque_off_write(raw)]


@contextlib.contextmanager
def other_core_busy(seconds: float, enabled: bool = True, burners: int = 1) -> Iterator[None]:
    """``burners`` busy-loop processes at normal priority for ``seconds`` (1: the other of
    two cores busy; 2: both); nothing when not ``enabled``."""
    with busy_cores(burners if enabled else 0, seconds):
        yield


def bench_rig(path: Path, tick_hz: float, baud: int = 1_000_000, **bus: Any) -> RigConfig:
    """bench3 at ``tick_hz`` written to ``path`` (a rig map the service and the guardian read)."""
    text = (CONFIG_DIR / "rigs" / "bench3.toml").read_text()
    values = {"tick_hz": tick_hz, "baud": baud, "read_divider": 4, "latency_timer_ms": 0.5} | bus
    for key, value in values.items():
        line = f"{key} = {value!r}".replace("'", '"')
        text, n = re.subn(rf"^{key} = .*$", line, text, flags=re.M)
        if not n:
            text = text.replace("[bus]\n", f"[bus]\n{line}\n", 1)
    path.write_text(text)
    return load_rig(path)


def decode_goals(raw: bytes) -> dict[int, int]:
    """Servo id -> Goal Position pulses of a goal SYNC_WRITE (4-byte items)."""
    body = raw[12:-2]
    return {body[i]: int.from_bytes(body[i + 1 : i + 5], "little", signed=True) for i in range(0, len(body) - 4, 5)}
