"""A/B of previs page variants: pages alternated in one browser, fps and CPU per frame.

bench_page's setup (the real service with the tail physics, the procedural trot into
/ws/horse at 120 Hz, Debian's headless Chromium with software WebGL at 1280x760); for
each round, each QUERY's page in turn (the order reversed every other round: ABBA),
render scale pinned (``--scale``, default 1.0), a few seconds to warm up, then
``--seconds`` measured: animation frames per second (a counter of its own) and the CPU
time of every Chromium process per animation frame (utime + stime from /proc: the GPU
process' SwiftShader, the renderer, viz). On a shared machine fps follows the load;
CPU per frame follows the work, so it is the figure to compare.

    PYTHONPATH=$PWD:$PWD/bench .venv/bin/python bench/ab_page.py [--rounds 4] [--seconds 6] QUERY QUERY ...

e.g. QUERY "" (meshes) and "?render=sticks" (primitives). docs/performance.md, "Previs page".
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path
from typing import Any

from bench.bench_page import served

TICKS = os.sysconf("SC_CLK_TCK")
COUNTER = """() => { window.__frames = 0;
  const f = () => { window.__frames++; requestAnimationFrame(f); }; requestAnimationFrame(f); }"""


def _stat(pid: int) -> tuple[int, float] | None:
    """(parent pid, CPU seconds) of a process, or None if it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()
    return int(fields[1]), (int(fields[11]) + int(fields[12])) / TICKS


def browser_cpu(exclude: int) -> float:
    """CPU seconds of this process' descendants, without the tree under ``exclude`` (the service)."""
    stats = {int(d): s for d in os.listdir("/proc") if d.isdigit() and (s := _stat(int(d))) is not None}
    children: dict[int, list[int]] = {}
    for pid, (ppid, _) in stats.items():
        children.setdefault(ppid, []).append(pid)
    total, todo = 0.0, list(children.get(os.getpid(), []))
    while todo:
        pid = todo.pop()
        if pid == exclude:
            continue
        total += stats[pid][1]
        todo += children.get(pid, [])
    return total


def measure(browser: Any, url: str, query: str, args: argparse.Namespace, service: int) -> tuple[float, float]:
    """(animation frames per second, Chromium CPU ms per animation frame) of one page."""
    page = browser.new_page(viewport={"width": 1280, "height": 760})
    page.goto(url + "/" + query)
    page.wait_for_function("() => window.riderlive && riderlive.connected && riderlive.frames > 10", timeout=120_000)
    page.evaluate("(s) => { riderlive.setView('perspective'); riderlive.setRenderScale(s); }", args.scale)
    page.evaluate(COUNTER)
    time.sleep(args.warm)
    (f0, t0), c0 = page.evaluate("() => [__frames, performance.now()]"), browser_cpu(service)
    time.sleep(args.seconds)
    (f1, t1), c1 = page.evaluate("() => [__frames, performance.now()]"), browser_cpu(service)
    page.close()
    frames = max(1, f1 - f0)
    return frames * 1000 / (t1 - t0), (c1 - c0) * 1000 / frames


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("queries", nargs="+")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--warm", type=float, default=3.0)
    ap.add_argument("--scale", type=float, default=1.0, help="render scale pinned on every page")
    args = ap.parse_args()
    results: dict[str, list[tuple[float, float]]] = {q: [] for q in args.queries}
    loads = []
    with served() as (url, pid, errors, browser):
        for r in range(args.rounds):
            for q in args.queries if r % 2 == 0 else args.queries[::-1]:
                results[q].append(measure(browser, url, q, args, pid))
                loads.append(os.getloadavg()[0])
    load = f"load average {min(loads):.1f}-{max(loads):.1f}"
    print(f"render scale {args.scale:g}, {args.rounds} rounds x {args.seconds:g} s, {load}")
    for q, rs in results.items():
        fps = " ".join(f"{f:.1f}" for f, _ in rs)
        cpu = " ".join(f"{c:.1f}" for _, c in rs)
        med_f = statistics.median(f for f, _ in rs)
        med_c = statistics.median(c for _, c in rs)
        print(f"/{q or '(meshes)':30s} fps median {med_f:5.1f} ({fps}); CPU/frame median {med_c:5.1f} ms ({cpu})")
    if errors:
        print(f"producer failed: {errors[0]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
