"""firmware_proto's host build: build it, run it on a pty, read its events; ``riderlive firmware-emu``.

    riderlive firmware-emu --profile platform6 --link /tmp/riderlive-platform
    riderlive firmware-emu --profile servo8 --name puppet --trace

The host build (``make -C firmware_proto host``) is the firmware's C core on a
pseudo-terminal with simulated actuators. It prints one JSON object a line (``ready`` with
the pty path first, then ``state``, ``park_step``, ``rx`` with ``--trace``, ``status``) and
takes commands on stdin (``status``, ``estop on|off``, ``stick I``, ``unstick I``, ``quit``).
Times are CLOCK_MONOTONIC ns, comparable with :func:`time.monotonic_ns`.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

FIRMWARE_DIR = Path(__file__).resolve().parents[2] / "firmware_proto"
HOST_BINARY = FIRMWARE_DIR / "build" / "fw_host"
PROFILES = ("platform6", "platform3", "servo8")

Event = dict[str, Any]


class FirmwareBuildError(RuntimeError):
    """firmware_proto is missing (an installed wheel has no C sources) or did not build."""


def build_host() -> Path:
    """``make -C firmware_proto host`` (a no-op when up to date); the binary's path."""
    if not (FIRMWARE_DIR / "Makefile").exists():
        raise FirmwareBuildError(f"{FIRMWARE_DIR}: no firmware sources (run from a riderlive clone)")
    result = subprocess.run(
        ["make", "-s", "-C", str(FIRMWARE_DIR), "host"], capture_output=True, text=True, check=False
    )
    if result.returncode != 0:
        raise FirmwareBuildError(f"make host failed (a C compiler is needed: ./install.sh):\n{result.stderr}")
    return HOST_BINARY


class FirmwareHost:
    """A running host build: its pty, its events, its stdin commands. A context manager."""

    def __init__(self, profile: str = "platform6", *, name: str | None = None, trace: bool = False) -> None:
        args = [str(build_host()), "--profile", profile, "--exit-on-eof"]
        if name:
            args += ["--name", name]
        if trace:
            args.append("--trace")
        self.process = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1)
        self.events: list[Event] = []
        self._changed = threading.Condition()
        self._reader = threading.Thread(target=self._read, name="fw-host-events", daemon=True)
        self._reader.start()
        ready = self.wait_event(lambda e: e["event"] == "ready", 10.0)
        self.port: str = ready["port"]
        self.ready = ready

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            event = json.loads(line)
            with self._changed:
                self.events.append(event)
                self._changed.notify_all()
        with self._changed:
            self.events.append({"event": "eof"})
            self._changed.notify_all()

    def wait_event(self, predicate: Callable[[Event], bool], timeout: float, start: int = 0) -> Event:
        """The first event from index ``start`` on that satisfies ``predicate``."""
        with self._changed:
            found: list[Event] = []

            def seen() -> bool:
                found[:] = [e for e in self.events[start:] if predicate(e)][:1]
                return bool(found) or any(e["event"] == "eof" for e in self.events)

            self._changed.wait_for(seen, timeout)
            if not found:
                raise TimeoutError(f"no such firmware event within {timeout} s; last: {self.events[-3:]}")
            return found[0]

    def send(self, line: str) -> None:
        assert self.process.stdin is not None
        self.process.stdin.write(line + "\n")
        self.process.stdin.flush()

    def status(self, timeout: float = 5.0) -> Event:
        """Ask for and return a fresh ``status`` event."""
        start = len(self.events)
        self.send("status")
        return self.wait_event(lambda e: e["event"] == "status", timeout, start)

    def states(self) -> list[str]:
        """Every state the firmware went through, in order."""
        with self._changed:
            return [e["to"] for e in self.events if e["event"] == "state"]

    def stop(self) -> list[Event]:
        """Quit it (then terminate, then kill) and return its events."""
        if self.process.poll() is None:
            try:
                self.send("quit")
                self.process.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                self.process.kill()
                self.process.wait()
        self._reader.join(timeout=5)
        return self.events

    def __enter__(self) -> FirmwareHost:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--profile", choices=PROFILES, default="platform6", help="actuator profile")
    parser.add_argument("--name", help="device name ARM must give (default: the profile's name)")
    parser.add_argument("--link", help="also make this path a symlink to the pty")
    parser.add_argument("--trace", action="store_true", help="print every frame the firmware accepts")
    parser.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0: Ctrl-C)")


def run(args: argparse.Namespace) -> int:
    try:
        binary = build_host()
    except FirmwareBuildError as exc:
        print(f"firmware-emu: {exc}", file=sys.stderr)
        return 2
    argv: Sequence[str] = [str(binary), "--profile", args.profile, "--duration", str(args.duration)]
    if args.name:
        argv = [*argv, "--name", args.name]
    if args.link:
        argv = [*argv, "--link", args.link]
    if args.trace:
        argv = [*argv, "--trace"]
    sys.stdout.flush()
    os.execv(str(binary), list(argv))  # the firmware's own process: Ctrl-C and stdin go to it
