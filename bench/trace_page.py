"""Where the previs page's frames go: a Chrome trace under bench_page's setup, per thread.

The same setup as bench/bench_page.py (the real service with the tail physics, the
procedural trot into /ws/horse at 120 Hz, Debian's headless Chromium with software
WebGL at 1280x760, render scale pinned at 0.5); for each page query, a trace of a few
seconds (categories: devtools.timeline, frame, cc, gpu, viz, blink) and, per thread,
its busy milliseconds per second of trace and per animation frame, with the events
that hold most of it (self time). Tracing slows the page: compare threads, not fps.

    PYTHONPATH=$PWD .venv/bin/python bench/trace_page.py [--seconds 5] [--save DIR] [QUERY ...]

e.g. QUERY "" (meshes) and "?render=sticks" (primitives). docs/performance.md, "Previs page".
"""

from __future__ import annotations

import argparse
import collections
import json
import threading
import time
from pathlib import Path
from typing import Any

from bench.bench_page import served

CATEGORIES = [
    "devtools.timeline",
    "disabled-by-default-devtools.timeline.frame",
    "cc",
    "gpu",
    "viz",
    "blink",
    "toplevel",
]


def trace(page: Any, seconds: float) -> list[dict[str, Any]]:
    """Trace events of `seconds` of the page (CDP Tracing, reported as events)."""
    cdp = page.context.new_cdp_session(page)
    events: list[dict[str, Any]] = []
    done = threading.Event()
    cdp.on("Tracing.dataCollected", lambda e: events.extend(e["value"]))
    cdp.on("Tracing.tracingComplete", lambda e: done.set())
    cdp.send("Tracing.start", {"traceConfig": {"includedCategories": CATEGORIES}, "transferMode": "ReportEvents"})
    time.sleep(seconds)
    cdp.send("Tracing.end")
    while not done.is_set():
        page.wait_for_timeout(50)
    return events


def per_thread(events: list[dict[str, Any]]) -> list[str]:
    """Lines: thread, busy ms per second and per frame, the events with most self time."""
    frames = sum(e.get("name") == "PageAnimator::serviceScriptedAnimations" for e in events)
    names: dict[tuple[int, int], str] = {}
    procs: dict[int, str] = {}
    spans: dict[tuple[int, int], list[dict[str, Any]]] = collections.defaultdict(list)
    for e in events:
        key = (e.get("pid", 0), e.get("tid", 0))
        if e.get("ph") == "M" and e["name"] == "thread_name":
            names[key] = e["args"]["name"]
        elif e.get("ph") == "M" and e["name"] == "process_name":
            procs[key[0]] = e["args"]["name"]
        elif e.get("ph") == "X" and "dur" in e:
            spans[key].append(e)
    stamps = [e["ts"] for es in spans.values() for e in es]
    if not stamps:
        return ["no trace events"]
    seconds = (max(stamps) - min(stamps)) / 1e6
    rows = []
    for key, es in spans.items():
        es.sort(key=lambda x: (x["ts"], -x["dur"]))
        own: collections.Counter[str] = collections.Counter()
        stack: list[dict[str, Any]] = []
        busy = 0.0
        for x in es:
            while stack and stack[-1]["ts"] + stack[-1]["dur"] <= x["ts"]:
                stack.pop()
            if stack:
                own[stack[-1]["name"]] -= x["dur"]
            else:
                busy += x["dur"]
            own[x["name"]] += x["dur"]
            stack.append(x)
        top = ", ".join(f"{n} {d / 1e3 / seconds:.0f}" for n, d in own.most_common(4))
        label = f"{procs.get(key[0], key[0])}/{names.get(key, key[1])}"
        per_s, per_frame = busy / 1e3 / seconds, busy / 1e3 / max(1, frames)
        rows.append((per_s, f"{label:42s} {per_s:6.0f} ms/s {per_frame:6.2f} ms/frame  ({top})"))
    head = f"{seconds:.1f} s traced, {frames} animation frames ({frames / seconds:.1f} fps while tracing)"
    return [head] + [row for per_s, row in sorted(rows, reverse=True) if per_s >= 5]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("queries", nargs="*", default=["", "?render=sticks"])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--save", type=Path, help="write each trace here (chrome://tracing, Perfetto)")
    args = ap.parse_args()
    with served() as (url, _, errors, browser):
        for query in args.queries:
            page = browser.new_page(viewport={"width": 1280, "height": 760})
            page.goto(url + "/" + query)
            live = "() => window.riderlive && riderlive.connected && riderlive.frames > 10"
            page.wait_for_function(live, timeout=120_000)
            page.evaluate("() => { riderlive.setView('perspective'); riderlive.setRenderScale(0.5); }")
            time.sleep(3)
            events = trace(page, args.seconds)
            print(f"\n== page /{query} (meshes unless ?render=sticks)")
            print("\n".join(per_thread(events)))
            if args.save:
                args.save.mkdir(parents=True, exist_ok=True)
                name = "".join(c if c.isalnum() else "_" for c in query) or "meshes"
                (args.save / f"trace_{name}.json").write_text(json.dumps({"traceEvents": events}))
            page.close()
    if errors:
        print(f"producer failed: {errors[0]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
