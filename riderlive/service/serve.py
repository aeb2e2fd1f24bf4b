"""``riderlive serve``: run the live service until SIGINT or SIGTERM."""

from __future__ import annotations

import argparse
import math
import socket
import sys

import uvicorn

from riderlive.configfile import ConfigError
from riderlive.service.config import ServiceConfig, load_config


def uvicorn_config(app: object, config: ServiceConfig, fd: int | None = None) -> uvicorn.Config:
    """uvicorn settings for frames: websockets impl, no per-message deflate, bounded messages."""
    return uvicorn.Config(
        app,  # type: ignore[arg-type]
        host=config.server.host,
        port=config.server.port,
        fd=fd,
        ws="websockets",
        ws_per_message_deflate=False,
        ws_max_size=max(4 * config.input.max_message_bytes, 1 << 20),
        log_level=config.server.log_level,
        timeout_graceful_shutdown=math.ceil(config.server.shutdown_timeout),
        lifespan="on",
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", help="service TOML (see config/service.example.toml)")
    parser.add_argument("--host", help="override server.host")
    parser.add_argument("--port", type=int, help="override server.port (0 = any free port)")


def run(args: argparse.Namespace) -> int:
    from riderlive.service.app import create_app

    try:
        config = load_config(args.config)
        overrides = {k: v for k, v in (("host", args.host), ("port", args.port)) if v is not None}
        if overrides:
            data = config.model_dump()
            data["server"].update(overrides)
            config = ServiceConfig.model_validate(data)
    except (ConfigError, ValueError) as exc:
        print(f"riderlive serve: {exc}", file=sys.stderr)
        return 2
    sock = None
    if config.server.port == 0:
        sock = socket.socket(socket.AF_INET6 if ":" in config.server.host else socket.AF_INET)
        sock.bind((config.server.host, 0))
        print(f"riderlive serve: listening on port {sock.getsockname()[1]}", file=sys.stderr, flush=True)
    server = uvicorn.Server(uvicorn_config(create_app(config), config))
    server.run(sockets=[sock] if sock else None)
    return 0
