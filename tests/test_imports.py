"""The import graph of riderlive/: no cycles (function-local and TYPE_CHECKING imports count) and
no import from a lower layer to a higher one (the layers of docs/architecture.md)."""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "riderlive"

LAYERS: dict[str, int] = {
    # 0: leaves, the vocabulary every layer may use
    **dict.fromkeys(
        ("channels", "units", "tickframe", "configfile", "framefile", "names", "ranges", "frameunits", "__init__"), 0
    ),
    **dict.fromkeys(("fastpath", "fastpath_core", "fastpath_cache", "fastpath_batch", "fastpath_llvm"), 0),
    **dict.fromkeys(("parquetstream", "timecode", "sched", "prometheus"), 0),
    # 1: the pure core (no I/O, no clocks)
    **dict.fromkeys(("skeleton", "rules", "horse", "saddle", "physics"), 1),
    # 2: offline edges over the core (files in, files out)
    **dict.fromkeys(("bake", "export", "takes", "plot", "vmc", "fit"), 2),
    # 3: devices (the lifecycle) and the hardware beside it
    **dict.fromkeys(("devices", "dynamixel", "platform"), 3),
    # 4: the tick process
    "realtime": 4,
    # 5: the web process and what it hosts
    **dict.fromkeys(("service", "bus", "client"), 5),
    # 6: the command line
    **dict.fromkeys(("cli", "__main__", "rig_drive", "rig_operator"), 6),
}
"""Top-level module or package of riderlive -> its layer (an import may only go to the same or a lower one)."""

UPWARD_EXCEPTIONS: set[tuple[str, str]] = set()
"""Known upward imports, each a debt named here (a new one fails the test)."""


def modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


@cache
def graph() -> dict[str, set[str]]:
    """Module -> the riderlive modules it imports (``from pkg import sub`` is an import of ``pkg.sub``);
    parsed once per run (the tests only read it)."""
    mods = modules()

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, set[str]] = {m: set() for m in mods}
    for module, path in mods.items():
        is_package = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text())):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = module.split(".") if is_package else module.split(".")[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                subs = [f"{source}.{a.name}" for a in node.names if f"{source}.{a.name}" in mods]
                targets = subs if len(subs) == len(node.names) else [*subs, source]
            for target in targets:
                found = resolve(target) if target.startswith("riderlive") else None
                if found is not None and found != module:
                    edges[module].add(found)
    return edges


def cycles(edges: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(component)

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def layer(module: str) -> int:
    top = module.split(".")[1] if "." in module else "__init__"
    assert top in LAYERS, f"{module}: give riderlive.{top} a layer in tests/test_imports.py and docs/architecture.md"
    return LAYERS[top]


def test_no_import_cycles() -> None:
    assert cycles(graph()) == []


def test_the_cycle_finder_finds_one() -> None:
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(edges) == [{"a", "b", "c"}]


def test_the_knots_issue_26_names_are_cut() -> None:
    edges = graph()
    assert "riderlive.bake" not in edges["riderlive.saddle.takes"]
    vmc = {m: edges[m] for m in edges if m.startswith("riderlive.vmc")}
    assert not [(a, b) for a, targets in vmc.items() for b in targets if b.startswith("riderlive.service")]
    assert "riderlive.service.runtime" not in edges["riderlive.service.devices_api"]
    service = {"riderlive.service.runtime", "riderlive.service.app"}
    assert not service & (edges["riderlive.bus.rig"] | edges["riderlive.bus.inbound"])
    assert "riderlive.service.runtime" not in edges["riderlive.service.ingest"] | edges["riderlive.service.publish"]
    assert "riderlive.service.ingest" not in edges["riderlive.service.ports"]


def test_no_import_goes_up_a_layer() -> None:
    edges = graph()
    upward = {
        (a, b)
        for a, targets in edges.items()
        for b in targets
        if layer(b) > layer(a) and (a, b) not in UPWARD_EXCEPTIONS
    }
    assert upward == set(), "imports from a lower layer to a higher one (docs/architecture.md)"
    stale = {(a, b) for a, b in UPWARD_EXCEPTIONS if b not in edges.get(a, set())}
    assert stale == set(), "an upward import was removed: drop it from UPWARD_EXCEPTIONS"


def test_the_emulator_and_the_platform_mechanism_stand_apart() -> None:
    """Issue 26's folders: nothing outside the emulator imports it (the live bus never loads it),
    and the platform's mechanism imports only the pure core, the vocabulary and the firmware's
    vocabulary (not the link, the device or the CLI beside it)."""
    edges = graph()
    emulator = "riderlive.dynamixel.emulator"
    users = {
        a for a, targets in edges.items() for b in targets if b.startswith(emulator) and not a.startswith(emulator)
    }
    assert users == set()
    mechanism = "riderlive.platform.mechanism"
    allowed = {"riderlive.platform.link_vocab"}
    reach = {
        b
        for a, targets in edges.items()
        if a.startswith(mechanism)
        for b in targets
        if not b.startswith(mechanism) and b not in allowed
    }
    assert {b for b in reach if layer(b) > 1} == set()
