"""Frame rate of the previs page in headless Chromium with 120 Hz input.

Starts the real service with the tail physics on (its own process, a free loopback
port; the skinned tail and the braid are published and drawn), streams the procedural
horse into /ws/horse at 120 Hz as a live producer (so the page's frames come from live
input at the tick rate), opens the page and samples the page's own counters
(``riderlive.fps``: animation frames per second; ``riderlive.frameRate``: websocket
frames per second) once a second. The page draws the skinned meshes; the baseline,
in the same run and browser, is the same page with today's primitives
(``?render=sticks``), measured before and after (halves of the baseline's seconds), and
an empty page that only counts animation frames. Target: median >= 55 fps with meshes.
The page picks its render scale (dynamic resolution, web/src/resolution.js) unless
``--scale X`` pins it on the meshes and the primitives pages alike; the seconds spent at
each scale are reported. Each page runs ``--warmup`` seconds (10) before it is sampled: from
scale 1, the dynamic resolution reaches its lowest step in 8 s.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_page.py [--seconds 20] [--scale 1.0]

Pictures for the docs: bench/page_shots.py.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

from playwright.sync_api import Browser, ViewportSize, sync_playwright
from websockets.sync.client import connect

import riderlive
from riderlive.channels import HORSE_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.web import CHROMIUM, CHROMIUM_ARGS, STATIC_DIR, static_size

BLANK = """<!doctype html><body><script>
window.riderlive = {fps: 0}; let n = 0, t0 = performance.now();
function f(now) { n++; if (now - t0 >= 1000) { riderlive.fps = n * 1000 / (now - t0); n = 0; t0 = now; }
  requestAnimationFrame(f); }
requestAnimationFrame(f);
</script></body>"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_server(workdir: Path) -> tuple[subprocess.Popen[bytes], str]:
    port = free_port()
    config = workdir / "service.toml"
    config.write_text(
        f'[server]\nport = {port}\n\n[takes]\ndirectory = "{workdir / "takes"}"\n\n[physics]\ntail = true\n'
    )
    root = Path(riderlive.__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root)}
    log = (workdir / "serve.log").open("wb")
    proc = subprocess.Popen(
        [sys.executable, "-m", "riderlive", "serve", "--config", str(config)], env=env, stdout=log, stderr=log
    )
    url = f"http://127.0.0.1:{port}"
    for _ in range(900):  # the tail kernels compile on a cold cache (10-20 s)
        try:
            urllib.request.urlopen(url + "/api/state", timeout=1).read()
            return proc, url
        except OSError:
            time.sleep(0.1)
    proc.kill()
    raise SystemExit("the service did not start")


def feed(url: str, stop: threading.Event, errors: list[str], rate: float = 120.0) -> None:
    """Stream the procedural horse into /ws/horse at ``rate`` Hz (deadline-paced)."""
    try:
        _feed(url, stop, rate)
    except Exception as exc:
        errors.append(repr(exc))


def _feed(url: str, stop: threading.Event, rate: float) -> None:
    horse = ProceduralHorse("trot", 4.0, seed=1)
    with connect(url.replace("http", "ws") + "/ws/horse", max_size=None) as ws:
        ws.send(json.dumps({"type": "hello", "name": "bench_page"}))
        t0 = time.perf_counter()
        k = 0
        while not stop.is_set():
            t = k / rate
            values = dict(zip(HORSE_NAMES, horse.sample(t), strict=True))
            ws.send(json.dumps({"t": t, "values": values}))
            k += 1
            delay = t0 + k / rate - time.perf_counter()
            if delay > 0:
                time.sleep(delay)


class Served(NamedTuple):
    """What :func:`served` yields."""

    url: str
    pid: int
    """The service's process."""
    feed_errors: list[str]
    """Why the 120 Hz producer stopped, if it did."""
    browser: Browser


@contextlib.contextmanager
def served(fed: bool = True) -> Iterator[Served]:
    """The service (:func:`start_server`, in a temporary directory), the procedural horse streamed
    into it at 120 Hz when ``fed`` (:func:`feed`), and headless Chromium; all stopped after."""
    with tempfile.TemporaryDirectory() as tmp:
        proc, url = start_server(Path(tmp))
        stop = threading.Event()
        errors: list[str] = []
        if fed:
            threading.Thread(target=feed, args=(url, stop, errors), daemon=True).start()
        try:
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=CHROMIUM, args=list(CHROMIUM_ARGS))
                yield Served(url, proc.pid, errors, browser)
                browser.close()
        finally:
            stop.set()
            proc.send_signal(signal.SIGINT)
            proc.wait(15)


def sample(page: object, seconds: float, warmup: float = 1.5) -> tuple[list[float], list[float], list[float]]:
    """One-second samples of (fps, websocket frames/s, render scale) after ``warmup`` seconds."""
    fps: list[float] = []
    rate: list[float] = []
    scale: list[float] = []
    time.sleep(warmup)
    for _ in range(int(seconds)):
        time.sleep(1.0)
        f, r, s = page.evaluate("() => [riderlive.fps, riderlive.frameRate || 0, riderlive.renderScale || 1]")  # type: ignore[attr-defined]
        fps.append(f)
        rate.append(r)
        scale.append(s)
    return fps, rate, scale


def solver_cost(n: int = 2000) -> tuple[float, float, float]:
    """Median microseconds: one rider pose, one horse pose, and (baseline) one rules frame."""
    from riderlive.horse import DEFAULT_SCALE
    from riderlive.rules import RiderModel
    from riderlive.skeleton import bone_quaternions, horse_pose

    horse = ProceduralHorse("trot", 4.0, seed=1)
    frames = [horse.sample(k / 120) for k in range(n)]
    model = RiderModel(scale=DEFAULT_SCALE)
    riders = [model.evaluate(f) for f in frames]

    def per_call(fn: object, items: list[list[float]]) -> float:
        times = []
        for item in items:
            t = time.perf_counter()
            fn(item)  # type: ignore[operator]
            times.append(time.perf_counter() - t)
        return statistics.median(times) * 1e6

    return per_call(bone_quaternions, riders), per_call(horse_pose, frames), per_call(model.evaluate, frames)


def scale_share(scales: list[float]) -> str:
    """Seconds at each render scale, largest scale first: '1.00 x12, 0.85 x8'."""
    counts = collections.Counter(round(s, 2) for s in scales)
    return ", ".join(f"{s:.2f} x{n}" for s, n in sorted(counts.items(), reverse=True))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=760)
    ap.add_argument("--scale", type=float, help="pin the render scale (0..1]; default: the page's automatic one")
    ap.add_argument(
        "--warmup", type=float, default=10.0, help="seconds before sampling a page (the dynamic resolution settles)"
    )
    args = ap.parse_args()
    if args.scale is not None and not 0 < args.scale <= 1:
        ap.error(f"--scale {args.scale}: expected a render scale in (0, 1]")

    with served() as (url, _, feed_errors, browser):
        viewport: ViewportSize = {"width": args.width, "height": args.height}
        blank = browser.new_page(viewport=viewport)
        blank.set_content(BLANK)
        base_fps, _, _ = sample(blank, min(args.seconds, 8))
        blank.close()

        def measure(query: str, seconds: float) -> tuple[list[float], list[float], list[float], Any]:
            page = browser.new_page(viewport=viewport)
            page.goto(url + "/" + query)
            page.wait_for_function("() => window.riderlive && riderlive.connected && riderlive.frames > 10")
            page.evaluate("() => riderlive.setView('perspective')")
            if args.scale is not None:
                page.evaluate("(s) => riderlive.setRenderScale(s)", args.scale)
            out = sample(page, seconds, args.warmup)
            return (*out, page)

        half = max(2.0, args.seconds / 2)
        sticks_fps, _, sticks_scale, sticks = measure("?render=sticks", half)
        sticks.close()
        fps, rate, scale, page = measure("", args.seconds)
        tail_drawn = page.evaluate("() => Object.keys(riderlive.values).some((n) => n.startsWith('tail_'))")
        driver = page.evaluate("() => riderlive.driver")
        tick_ms = page.evaluate("() => riderlive.tickMs")
        state = json.loads(urllib.request.urlopen(url + "/api/state", timeout=5).read())
        fed = sum(p["accepted"] for p in state["arbitration"]["producers"])
        page.close()
        more, _, more_scale, sticks = measure("?render=sticks", half)
        sticks.close()
        sticks_fps += more
        sticks_scale += more_scale

    rider_us, horse_us, rules_us = solver_cost()
    med = statistics.median(fps)
    base = statistics.median(base_fps)
    print(f"input: procedural trot streamed into /ws/horse at 120 Hz ({fed} frames accepted); page driver: {driver}")
    if feed_errors:
        print(f"producer failed: {feed_errors[0]}")
    print(f"viewport {args.width}x{args.height}, {len(fps)} one-second samples")
    p10 = sorted(fps)[len(fps) // 10]
    print(f"page fps      median {med:.1f}  p10 {p10:.1f}  min {min(fps):.1f}  max {max(fps):.1f}")
    print("fps by second " + " ".join(f"{f:.0f}" for f in fps))
    print(f"frames in/s   median {statistics.median(rate):.1f}  min {min(rate):.1f}")
    print(f"JS per animation frame {tick_ms:.2f} ms (pose both skeletons, update the scene, submit GL, plots)")
    how = f"pinned at {args.scale:g} (--scale)" if args.scale is not None else "automatic: dynamic resolution"
    print(f"render scale  {how}; seconds at each: {scale_share(scale)}")
    print(f"              primitives: {scale_share(sticks_scale)}")
    print(f"load average  {os.getloadavg()[0]:.1f} (2 cores, shared)")
    sticks_med = statistics.median(sticks_fps)
    print(f"skinned tail and braid drawn: {tail_drawn}")
    print(f"baseline fps  primitives (?render=sticks, before and after) median {sticks_med:.1f}")
    print(f"baseline fps  (empty page, same browser) median {base:.1f}")
    print(f"ratio meshes/primitives {med / sticks_med:.2f}, meshes/empty page {med / base:.2f}")
    print(f"python solver: rider pose {rider_us:.0f} us, horse pose {horse_us:.0f} us per frame")
    print(f"  (baseline: the rules, one frame {rules_us:.1f} us; ratio rider/rules {rider_us / rules_us:.0f})")
    print(f"bundle {static_size() / 1e6:.3f} MB in {STATIC_DIR.name}/ (budget 1.5 MB)")
    slow = sum(f < 30.0 for f in fps)
    print("PASS: median >= 55 fps with meshes" if med >= 55.0 else f"BELOW TARGET: median {med:.1f} < 55 fps")
    print(">= 30 fps every second" if slow == 0 else f"below 30 fps in {slow} of {len(fps)} seconds")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
