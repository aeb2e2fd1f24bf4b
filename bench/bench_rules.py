"""Rule engine speed: the live scalar path and the NumPy batch path.

    .venv/bin/python bench/bench_rules.py [--frames 1000000]

Prints the scalar path's median time per frame with its ratio to a plain
dict-in/dict-out implementation of the same equations (the baseline, measured in the
same run), and the batch path's frames per second on one core (pinned) for N frames,
cold (first call, fresh memory) and warm (best of five).
Targets (issue 2): scalar <= 5 us median; batch >= 5 million frames/s at N = 1e6.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from riderlive.channels import HORSE_NAMES
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import RuleParams


def plain_rules(h: dict[str, float], p: RuleParams) -> dict[str, float]:
    """The baseline: Appendix B written the obvious way, dict in, dict out."""
    lb, wr, ft = p.lower_back, p.wrists, p.feet
    front_h = h["lfHoof.ty"] + h["rfHoof.ty"]
    back_h = h["lbHoof.ty"] + h["rbHoof.ty"]
    all_h = front_h + back_h
    front_x = h["rearPivot.tx"] - (h["lfHoof.tx"] + h["rfHoof.tx"]) / 2
    back_x = h["rearPivot.tx"] - (h["lbHoof.tx"] + h["rbHoof.tx"]) / 2
    pitch, roll = h["rearPivot.rz"], h["rearPivot.rx"]
    lower = (
        pitch * (h["rearPivot.ty"] + lb.pivot_height_offset) * lb.pivot_weight
        + back_x * lb.back_feet_weight
        - front_x * lb.front_feet_weight
        + (min(front_h, 18.0) * (abs(pitch) + 5) * 0.1 * 0.9 - min(back_h, 15.0) * 0.4) * 0.4
    )
    lift = min(
        (abs(h["lbHoof.tx"] - h["rbHoof.tx"]) + abs(h["lfHoof.tx"] - h["rfHoof.tx"]) - back_x + front_x + front_h * 2)
        * 0.01,
        15.0,
    )
    shift = max(-1.0, min(1.0, (pitch * 2 - lower) * 0.1))
    back17 = max(-17.0, min(17.0, lower))
    h15 = min(all_h, ft.height_limit)
    reach = front_x * -(abs(pitch) * 0.005 + 0.08 + h["backMid.rz"] * 0.02)
    foot_tx = min(reach, 0.0) - abs(pitch) * lower * 0.005
    belly = h15 * -0.05 + 2 - roll * 0.05
    out = {
        "lower_back.rz": lower,
        "lower_back.ry": -roll,
        "lower_back.rx": -roll * 0.5,
        "waist.rz": lower * 1.7,
        "hip.rz": lower * 0.8,
        "hip.ry": roll * 0.5 + (h["rbHoof.ty"] - h["lbHoof.ty"]) * 2,
        "cog.ty": lift,
        "cog.tx": shift,
    }
    for name, rest in (("spine_c", 0.482), ("spine_d", 0.564), ("spine_f", 0.949)):
        out[f"{name}.ty"] = rest - 0.1 + lift / 6
    out["neck.ty"] = 1.392 - 0.1 + lift / 7
    out["head_a.ty"] = 1.002 - 0.1 + lift / 7
    out["head.rz"] = -max(-20.0, min(17.0, lower)) * 0.9 - lift * 18 + 5
    out["head.ry"] = roll * 0.8
    for side in ("lf", "rt"):
        out[f"{side}_wrist.tz"] = back17 * wr.back_gain - front_x * abs(pitch) * wr.pivot_gain
        out[f"{side}_wrist.ty"] = min(all_h, 20.0) * 0.03 - h["rearPivot.ty"] * 0.0005
        out[f"{side}_foot.tx"] = foot_tx
        out[f"{side}_foot.rz"] = (foot_tx + 3) * -6 * 2
        out[f"{side}_foot.ry"] = h15 * -1.7 - 1
        out[f"{side}_foot.rx"] = h15 * (0.1 if side == "lf" else -0.1) + 1
        out[f"{side}_foot.tz"] = belly
        out[f"{side}_knee.tz"] = -belly * 1.1
        out[f"{side}_knee.ty"] = h15 * 0.03 - 1
    out["hair.up"] = (all_h - 2) * 0.7
    out["hair.side"] = (all_h - 2) * -roll * -0.02
    out["cloth.up"] = (all_h - 2) * 0.7
    out["cloth.side"] = roll * -0.5 + (h["rbHoof.ty"] - h["lbHoof.ty"]) * -2
    return out


def median_us(fn, frames: list, repeats: int = 7) -> float:  # type: ignore[no-untyped-def,type-arg]
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for frame in frames:
            fn(frame)
        samples.append((time.perf_counter() - start) / len(frames) * 1e6)
    return statistics.median(samples)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=1_000_000)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})  # one core

    rng = np.random.default_rng(0)
    horse = rng.uniform(-8.0, 8.0, size=(args.frames, len(HORSE_NAMES)))
    model = RiderModel()
    params = model.params

    frames = horse[:20_000].tolist()
    dicts = [dict(zip(HORSE_NAMES, f, strict=True)) for f in frames]
    ours = median_us(model.evaluate, frames)
    base = median_us(lambda d: plain_rules(d, params), dicts)
    print(f"scalar path: {ours:.2f} us/frame median (target <= 5)")
    print(f"  baseline dict-in/dict-out: {base:.2f} us/frame; ratio ours/baseline = {ours / base:.2f}")

    start = time.perf_counter()
    model.evaluate_batch(horse)
    cold = args.frames / (time.perf_counter() - start)
    warm_times = []
    for _ in range(5):
        start = time.perf_counter()
        model.evaluate_batch(horse)
        warm_times.append(time.perf_counter() - start)
    warm = args.frames / min(warm_times)
    print(
        f"batch path, N={args.frames:,}, one core: {warm / 1e6:.2f} M frames/s warm (best of 5), "
        f"{cold / 1e6:.2f} M frames/s cold (target >= 5)"
    )
    print(f"  ratio batch/scalar throughput = {warm / (1e6 / ours):.0f}x")


if __name__ == "__main__":
    main()
