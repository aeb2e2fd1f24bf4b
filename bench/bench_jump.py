"""What the ``[jump]`` layer costs a live frame: ``RiderModel.evaluate`` with it and without.

    .venv/bin/python bench/bench_jump.py [--rounds 9] [--burn 0]

Frames: the procedural canter (10 s, where the layer only tests its gate) and the jump
shot (``config/shots/jump.toml``: about a quarter of its frames are over the fence), at
120 Hz, length scale 25. Per frame, median over ``--rounds`` rounds that take the two
measurements in turn; the ratio is the figure to compare (absolute numbers drift on a
shared host). ``--burn N`` starts N busy-loop processes for the run (a loaded host).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from bench.serving import busy_cores
from riderlive.channels import HORSE_NAMES
from riderlive.horse import DEFAULT_SCALE
from riderlive.horse.script import gait_script, generate, load_script
from riderlive.rules import RiderModel
from riderlive.rules.params import RuleParams


def _per_frame(model: RiderModel, frames: list[list[float]]) -> float:
    start = time.perf_counter()
    for frame in frames:
        model.evaluate(frame)
    return (time.perf_counter() - start) / len(frames) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--burn", type=int, default=0, help="busy processes during the run")
    args = parser.parse_args()
    with busy_cores(args.burn, 3600) as state:
        on = RiderModel(scale=DEFAULT_SCALE)
        off = RiderModel(RuleParams().with_values({"jump.weight": 0.0}), scale=DEFAULT_SCALE)
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        takes = {
            "canter": generate(gait_script("canter", 10.0), 120.0),
            "jump shot": generate(load_script(os.path.join(root, "config", "shots", "jump.toml")), 120.0),
        }
        print(f"{state}, load average {os.getloadavg()[0]:.1f}")
        for name, table in takes.items():
            frames = np.column_stack([table.column(n) for n in HORSE_NAMES]).tolist()
            with_layer, without = [], []
            for _ in range(args.rounds):
                without.append(_per_frame(off, frames))
                with_layer.append(_per_frame(on, frames))
            a, b = statistics.median(without), statistics.median(with_layer)
            print(f"{name}: evaluate {b:.2f} us/frame with [jump], {a:.2f} without (baseline), ratio {b / a:.3f}")


if __name__ == "__main__":
    main()
