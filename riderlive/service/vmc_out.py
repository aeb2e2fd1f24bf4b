"""The VMC sender the service runs: one non-blocking UDP socket, one bundle per chosen tick
(the protocol itself: ``riderlive.vmc``).

Where it runs: in the web process, called from the tick callback right after the
websocket fan-out (``Service.on_tick``), on the records that callback already read.
The tick process never sees it. The web loop pays the pose and the encoding (a few
hundred microseconds per bundle, ``bench/bench_vmc.py``) and never waits on the
network: the socket is non-blocking, so a full send buffer drops that bundle
(counted in ``dropped``) instead of blocking, and a send error (no route, an ICMP
"port unreachable" from a receiver that is not running) is counted in ``errors`` and
the next bundle is tried as usual. One bundle (per target) goes out per callback, for
the newest chosen tick (``seq`` a multiple of the decimation); every chosen tick before
it that got none (several arrived at once after the web loop was late, or never
reached the web process) is counted in ``skipped``, per bundle: ``sent + dropped +
error + skipped`` is the number of bundles the rate asked for. Names are resolved once, at start: a host that
does not resolve, or a local port in use, is a :class:`VmcError` before the service
starts.
"""

from __future__ import annotations

import errno
import socket
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from riderlive.realtime.record import RecordLayout
from riderlive.service.config import VmcSection
from riderlive.service.poses import RecordPoses
from riderlive.skeleton import HORSE_RIG
from riderlive.vmc.performer import horse_bundle, rider_bundle
from riderlive.vmc.target import DEFAULT_PORT, VmcError, parse_target

OUTCOMES = ("sent", "dropped", "error", "skipped")
"""What became of each bundle the rate asked for (``VmcSender.counts``)."""

__all__ = ["DEFAULT_PORT", "VmcError", "VmcSender", "parse_target", "resolve"]


def resolve(host: str, port: int, what: str = "VMC target") -> tuple[int, tuple[str, int]]:
    """(address family, socket address) of a UDP target, or :class:`VmcError`."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise VmcError(f"{what} {host}:{port}: cannot resolve host {host!r} ({exc})") from None
    family, _, _, _, address = infos[0]
    return family, (str(address[0]), int(address[1]))


@dataclass
class VmcSender:
    """Rider (and optionally horse) bundles to their targets; see the module docstring."""

    poses: RecordPoses
    rider: tuple[int, tuple[str, int]]
    horse: tuple[int, tuple[str, int]] | None = None
    decimation: int = 1
    local_port: int = 0
    counts: Counter[str] = field(default_factory=Counter)
    """Bundles by outcome: ``sent``, ``dropped`` (send buffer full), ``error``, ``skipped``
    (a chosen tick that got no bundle)."""
    last_seq: int | None = None
    """The last chosen tick a bundle was made for."""
    last_error: str | None = None
    timecode: Callable[[np.ndarray], str] | None = None
    """A record's SMPTE label, appended to ``/VMC/Ext/T`` (None: time only)."""
    _socket: socket.socket = field(init=False)
    _start: float | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        family = self.rider[0]
        if self.horse is not None and self.horse[0] != family:
            raise VmcError("the rider and horse VMC targets must both be IPv4 or both IPv6")
        if self.horse is not None and self.horse[1] == self.rider[1]:
            raise VmcError(f"the rider and the horse need different VMC targets (both {self.rider[1]})")
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.bind(("::" if family == socket.AF_INET6 else "0.0.0.0", self.local_port))
        except OSError as exc:
            sock.close()
            raise VmcError(f"VMC local port {self.local_port}: {exc.strerror}") from None
        sock.setblocking(False)
        self._socket = sock

    @classmethod
    def open(
        cls, poses: RecordPoses, config: VmcSection, tick_rate: float, counts: Counter[str] | None = None
    ) -> VmcSender:
        """Resolve the configured targets (``HOST:PORT``) and open the socket."""
        if config.target is None:
            raise VmcError("no VMC target configured (vmc.target or serve --vmc HOST:PORT)")
        rider = resolve(*parse_target(config.target, "VMC target"), "VMC target")
        horse = None
        if config.horse_target is not None:
            horse = resolve(*parse_target(config.horse_target, "VMC horse target"), "VMC horse target")
        decimation = max(1, round(tick_rate / config.rate))
        return cls(poses, rider, horse, decimation, config.local_port, Counter() if counts is None else counts)

    def publish(self, records: list[np.ndarray]) -> None:
        """Send the newest of ``records`` whose ``seq`` is a multiple of the decimation."""
        record = next((r for r in reversed(records) if RecordLayout.seq.count(r) % self.decimation == 0), None)
        if record is None:
            return
        seq = RecordLayout.seq.count(record)
        if self.last_seq is not None and seq > self.last_seq:
            missed = (seq - self.last_seq) // self.decimation - 1
            self.counts["skipped"] += missed * (1 if self.horse is None else 2)
        self.last_seq = seq  # a restarted tick's seq starts again: counted from there
        engine_t = RecordLayout.engine_t.at(record)
        if self._start is None:
            self._start = engine_t
        t = engine_t - self._start
        horse = self.poses.horse(record)
        saddle = HORSE_RIG.index["saddle"]
        label = "" if self.timecode is None else self.timecode(record)
        root = (horse.world_positions[saddle], horse.world_rotations[saddle])
        self._send(rider_bundle(self.poses.rider(record), *root, t, label), self.rider[1])
        if self.horse is not None:
            self._send(horse_bundle(horse, HORSE_RIG.names, t, label), self.horse[1])

    def _send(self, data: bytes, address: tuple[str, int]) -> None:
        try:
            self._socket.sendto(data, address)
            self.counts["sent"] += 1
        except BlockingIOError:
            self.counts["dropped"] += 1
        except OSError as exc:
            if exc.errno == errno.ENOBUFS:
                self.counts["dropped"] += 1
            else:
                self.counts["error"] += 1
                self.last_error = f"{address[0]}:{address[1]}: {exc.strerror or exc}"

    def status(self) -> dict[str, object]:
        return {
            "target": f"{self.rider[1][0]}:{self.rider[1][1]}",
            "horse_target": None if self.horse is None else f"{self.horse[1][0]}:{self.horse[1][1]}",
            "decimation": self.decimation,
            **{outcome: self.counts[outcome] for outcome in OUTCOMES},
            "last_error": self.last_error,
        }

    def close(self) -> None:
        self._socket.close()
