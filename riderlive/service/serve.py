"""``riderlive serve``: run the live service until SIGINT or SIGTERM.

SIGINT and SIGTERM are an e-stop of every device (torque off at once, latched), then a
clean shutdown. The exit status says which signal stopped it, whatever the disposition
the process inherited: 130 after SIGINT; after SIGTERM the process ends by the signal
(143 where SIGTERM was ignored). ``--arm`` arms the rig once it is connected, at start
only: for unattended installations, at the risk that it moves with nobody watching.
"""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import math
import os
import signal
import socket
import sys
from types import FrameType

import uvicorn

from riderlive.configfile import ConfigError, validate
from riderlive.devices.latch import StopSource
from riderlive.devices.registry import DeviceSpec
from riderlive.sched import normal_priority_thread, try_realtime_priority
from riderlive.service.config import ServiceConfig, load_config
from riderlive.service.hostcheck import Advice, advise, device_ports, gather
from riderlive.service.runtime import Service
from riderlive.service.wsprotocol import protocol_class


def uvicorn_config(app: object, config: ServiceConfig, fd: int | None = None) -> uvicorn.Config:
    """uvicorn settings for frames: websockets impl, no per-message deflate, bounded messages."""
    return uvicorn.Config(
        app,  # type: ignore[arg-type]
        host=config.server.host,
        port=config.server.port,
        fd=fd,
        ws=protocol_class(config.publish.send_buffer_bytes),
        ws_per_message_deflate=False,
        ws_max_size=max(4 * config.input.max_message_bytes, 1 << 20),
        log_level=config.server.log_level,
        timeout_graceful_shutdown=math.ceil(config.server.shutdown_timeout),
        lifespan="on",
        loop=config.server.loop,
    )


ABANDON_AFTER = 2
"""Ctrl+C presses after the first (which began the stop) that abandon the stop."""


class RiderServer(uvicorn.Server):
    """uvicorn's server, saying goodbye to websocket clients before it drops them."""

    def __init__(self, config: uvicorn.Config, service: Service) -> None:
        super().__init__(config)
        self.service = service
        self.interrupts_while_stopping = 0
        """Ctrl+C pressed after the stop began (:data:`ABANDON_AFTER` of them force the exit)."""
        self.stopped_by: int | None = None
        """The signal that began the stop (None: none did)."""

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        """``asyncio.to_thread`` work (bakes, upload checks, recovering a take) at normal priority,
        whatever the event loop's thread runs at (``server.realtime_priority``)."""
        executor = concurrent.futures.ThreadPoolExecutor(
            thread_name_prefix="riderlive-worker", initializer=normal_priority_thread
        )
        asyncio.get_running_loop().set_default_executor(executor)
        await super().startup(sockets)

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        await self.service.hub.goodbye("shutdown")
        await super().shutdown(sockets)

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        """SIGINT/SIGTERM of the process that drives the devices: e-stop first.

        uvicorn forces an exit at the second Ctrl+C, which cancels the app's shutdown (the
        devices' park, the take's last rows, the guardian's stop) and prints a traceback; a
        second Ctrl+C while the stop runs is only answered, the third abandons it (the
        guardian then parks what was armed, the take is recovered at the next start)."""
        supervisor = getattr(self.service, "supervisor", None)
        if supervisor is not None:
            supervisor.estop(StopSource.SIGNAL)
        if self.stopped_by is None:
            self.stopped_by = sig
        if self.should_exit and sig == signal.SIGINT:
            self.interrupts_while_stopping += 1
            if self.interrupts_while_stopping < ABANDON_AFTER:
                print(
                    "riderlive serve: stopping (parking the devices, closing the take); "
                    "Ctrl+C once more abandons it and leaves the park to the guardian",
                    file=sys.stderr,
                    flush=True,
                )
                return
            print("riderlive serve: stop abandoned", file=sys.stderr, flush=True)
        super().handle_exit(sig, frame)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", help="service TOML (see config/service.example.toml)")
    parser.add_argument("--host", help="override server.host")
    parser.add_argument("--port", type=int, help="override server.port (0 = any free port)")
    parser.add_argument(
        "--tail", action="store_true", help="run the tail and braid physics (physics.tail = true; see docs/tail.md)"
    )
    parser.add_argument("--vmc", metavar="HOST:PORT", help="send the rider as a VMC performer (docs/vmc.md)")
    parser.add_argument("--vmc-horse", metavar="HOST:PORT", help="send the horse too, to another port")
    parser.add_argument("--vmc-rate", type=float, metavar="HZ", help="VMC bundles per second (default 60)")
    parser.add_argument("--nats", metavar="URL", help="join a stage over NATS: nats://HOST:4222 (docs/deployment.md)")
    parser.add_argument("--stage", metavar="NAME", help="the stage to join (nats.stage)")
    parser.add_argument("--rig", metavar="NAME", help="this rig's name on the stage (nats.rig; must be unique)")
    parser.add_argument(
        "--foxglove",
        type=int,
        metavar="PORT",
        help="serve the Foxglove WebSocket protocol (docs/foxglove.md; 0: any port)",
    )
    parser.add_argument(
        "--arm",
        action="store_true",
        help="arm the rig once connected, at start only (rig.arm = true): unattended use, it moves unwatched",
    )


def warn_host(devices: tuple[DeviceSpec, ...], config: ServiceConfig) -> list[Advice]:
    """With a serial device configured: what this host should change for it, printed
    with the fix (service/hostcheck.py, docs/deployment.md "A busy host")."""
    if not devices:
        return []
    advice = advise(
        gather(device_ports(devices)),
        config.tick.realtime_priority,
        config.server.realtime_priority,
        config.host.kernel_workers_priority,
    )
    for a in advice:
        print(f"riderlive serve: warning: {a}", file=sys.stderr, flush=True)
    return advice


def run(args: argparse.Namespace) -> int:
    from riderlive.service.app import create_app

    try:
        config = load_config(args.config)
        overrides = {k: v for k, v in (("host", args.host), ("port", args.port)) if v is not None}
        vmc = {
            k: v
            for k, v in (
                ("target", getattr(args, "vmc", None)),
                ("horse_target", getattr(args, "vmc_horse", None)),
                ("rate", getattr(args, "vmc_rate", None)),
            )
            if v is not None
        }
        stage = {
            k: v
            for k, v in (
                ("url", getattr(args, "nats", None)),
                ("stage", getattr(args, "stage", None)),
                ("rig", getattr(args, "rig", None)),
            )
            if v is not None
        }
        foxglove = getattr(args, "foxglove", None)
        if (
            overrides
            or vmc
            or stage
            or foxglove is not None
            or getattr(args, "tail", False)
            or getattr(args, "arm", False)
        ):
            data = config.model_dump()
            if foxglove is not None:
                data["foxglove"]["port"] = foxglove
            data["nats"].update(stage)
            data["server"].update(overrides)
            data["vmc"].update(vmc)
            if getattr(args, "tail", False):
                data["physics"]["tail"] = True
            if getattr(args, "arm", False):
                data["rig"]["arm"] = True
            config = validate(ServiceConfig, data, "command line")
    except (ConfigError, ValueError) as exc:
        print(f"riderlive serve: {exc}", file=sys.stderr)
        return 2
    if config.nats.url is not None:
        from riderlive.bus.stage import preflight

        problem = preflight(config.nats)
        if problem is not None:
            print(f"riderlive serve: {problem}", file=sys.stderr)
            return 2
    try:
        app = create_app(config)
    except (ConfigError, ValueError) as exc:
        print(f"riderlive serve: {exc}", file=sys.stderr)
        return 2
    try:
        sock = socket.socket(socket.AF_INET6 if ":" in config.server.host else socket.AF_INET)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((config.server.host, config.server.port))
        sock.listen(2048)
    except OSError as exc:
        print(f"riderlive serve: cannot listen on {config.server.host}:{config.server.port}: {exc}", file=sys.stderr)
        return 2
    port = sock.getsockname()[1]
    print(
        f"riderlive serve: listening on port {port} (http://{config.server.host}:{port}/)", file=sys.stderr, flush=True
    )
    if config.server.nice:
        try:
            os.setpriority(os.PRIO_PROCESS, 0, config.server.nice)
        except OSError as exc:
            print(f"riderlive serve: warning: cannot set nice {config.server.nice}: {exc}", file=sys.stderr)
    if config.server.realtime_priority:
        try_realtime_priority(config.server.realtime_priority, reset_on_fork=True, who="the web process")
    service = app.state.service
    warn_host(service.devices, config)
    server = RiderServer(uvicorn_config(app, config), service)
    try:
        server.run(sockets=[sock])
    except KeyboardInterrupt:  # uvicorn re-raises Ctrl+C after its clean shutdown
        return 128 + signal.SIGINT
    finally:
        if service.vmc is not None:
            print(f"riderlive serve: VMC out: {service.vmc.status()}", file=sys.stderr, flush=True)
    # uvicorn re-raises the signal with the disposition the process inherited: one started with
    # SIGINT ignored (a background job of a script, a test worker) got here after a Ctrl+C
    return 0 if server.stopped_by is None else 128 + server.stopped_by
