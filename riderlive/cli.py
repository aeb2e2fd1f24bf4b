"""The ``riderlive`` command: one subcommand per module, imported only when used."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from riderlive import __version__

COMMANDS: dict[str, tuple[str, str]] = {
    "bake": ("riderlive.bake", "evaluate the rider rules on a horse take"),
    "horse": ("riderlive.horse.cli", "write a procedural horse take (gait or shot script)"),
    "saddle": ("riderlive.saddle.cli", "write the saddle pose of a horse; rebuild a horse from a saddle"),
    "plot": ("riderlive.plot", "plot channels of a frame file over time"),
    "servo-emu": ("riderlive.dynamixel.emulator.cli", "run an emulated Dynamixel bus on a pseudo-terminal"),
    "firmware-emu": ("riderlive.platform.firmware_host", "run firmware_proto's host build on a pseudo-terminal"),
    "platform": ("riderlive.platform.cli", "bake a take to motion-platform actuator tracks; describe a platform"),
    "tail": ("riderlive.physics.cli", "run the horse tail and rider braid physics on a horse take"),
    "rig": ("riderlive.rig_drive", "check a servo map; drive it with a procedural horse"),
    "serve": ("riderlive.service.serve", "run the live service (websockets, REST, the tick)"),
    "export": ("riderlive.export.cli", "write a take as BVH or glTF (.glb) for engines and Blender"),
    "fit": ("riderlive.fit.cli", "fit a preset to horse takes and the rider recorded with them"),
    "host": ("riderlive.service.host_cli", "check this host for serial devices; raise the kernel's workers"),
    "stage": ("riderlive.bus.stage", "a stage over NATS: list its rigs, e-stop them all, heartbeat, takes"),
}
"""Subcommand -> (module with ``add_arguments`` and ``run``, one-line help)."""


def build_parser(selected: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="riderlive", description="A horse's motion in, a rider's reaction out.")
    parser.add_argument("--version", action="version", version=f"riderlive {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_name, summary) in COMMANDS.items():
        sub_parser = sub.add_parser(name, help=summary, description=summary)
        if name == selected:
            importlib.import_module(module_name).add_arguments(sub_parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    selected = next((a for a in argv if a in COMMANDS), None)
    args = build_parser(selected).parse_args(argv)
    if args.command is None:
        build_parser().print_help()
        return 2
    module = importlib.import_module(COMMANDS[args.command][0])
    result: int = module.run(args)
    return result


if __name__ == "__main__":
    raise SystemExit(main())
