"""Regenerate the page's pictures in docs/img: every gait, every move, the camera views.

Starts the real service with the tail physics on (as bench_page.py does), opens the page
in headless Chromium, pins the procedural horse to each gait and asks it for each move,
and saves the 3D view as drawn (``riderlive.snapshot()``: the canvas right after a frame)
at the move's moment: the horse's pitch (``rearPivot.rz``) passing the value below.

    PYTHONPATH=$PWD .venv/bin/python bench/page_shots.py [--out docs/img]
"""

from __future__ import annotations

import argparse
import base64
import io
import json
import time
import urllib.request
from pathlib import Path
from typing import Any

from PIL import Image

from bench.bench_page import served

GAITS = {"walk": 1.6, "trot": 4.0, "canter": 6.0, "gallop": 11.0}
MOVES = {  # move: (gait it starts from, pitch in degrees that marks the moment: > if positive, < if negative)
    "jump": ("canter", 14.0),
    "rear": ("walk", 30.0),
    "stop": ("canter", 7.0),
    "buck": ("trot", -12.0),
}
VIEWS = ("perspective", "side", "front", "rear", "rider", "top")


def rest(url: str, method: str, path: str, body: Any) -> None:
    req = urllib.request.Request(url + path, data=json.dumps(body).encode(), method=method)
    req.add_header("content-type", "application/json")
    urllib.request.urlopen(req, timeout=10).read()


def save(page: Any, path: Path) -> None:
    shot = page.evaluate("riderlive.snapshot()")
    png = base64.b64decode(shot["image"].split(",", 1)[1])
    Image.open(io.BytesIO(png)).convert("RGB").quantize(colors=128).save(path, optimize=True)
    print(f"wrote {path}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("docs/img"))
    ap.add_argument("--moves-only", action="store_true", help="skip the gaits")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    with served(fed=False) as (url, _, _, browser):
        page = browser.new_page(viewport={"width": 1200, "height": 800})
        page.goto(url + "/")
        page.wait_for_function("() => window.riderlive && riderlive.frames > 10")
        page.evaluate("riderlive.setRenderScale(1)")
        page.evaluate("riderlive.setView('perspective')")
        for gait, speed in GAITS.items() if not args.moves_only else ():
            rest(url, "PUT", "/api/source", {"kind": "procedural", "gait": gait, "speed": speed})
            time.sleep(2.5)  # the blend into the gait
            save(page, args.out / f"page_gait_{gait}.png")
        page.evaluate("riderlive.setView('side')")
        for move, (gait, pitch) in MOVES.items():
            rest(url, "PUT", "/api/source", {"kind": "procedural", "gait": gait, "speed": GAITS[gait]})
            time.sleep(2.5)
            rest(url, "POST", "/api/horse/perform", {"move": move})
            test = f"> {pitch}" if pitch > 0 else f"< {pitch}"
            page.wait_for_function(f"() => riderlive.values['rearPivot.rz'] {test}", timeout=15000)
            save(page, args.out / f"page_move_{move}.png")
        rest(url, "PUT", "/api/source", {"kind": "procedural", "gait": "trot", "speed": 4.0})
        time.sleep(2.5)
        for view in VIEWS:
            page.evaluate(f"riderlive.setView('{view}')")
            time.sleep(0.3)
            save(page, args.out / f"page_view_{view}.png")
        page.evaluate("riderlive.setView('perspective')")
        page.screenshot(path=str(args.out / "page.png"))
        Image.open(args.out / "page.png").convert("RGB").quantize(colors=128).save(args.out / "page.png")
        print(f"wrote {args.out / 'page.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
