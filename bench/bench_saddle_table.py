"""The saddle estimator's accuracy table (docs/saddle.md): lock, correlation, re-lock, per gait.

For each gait, seeded cases (a speed drawn within the gait's range, a sample rate of
30, 120 or 500 Hz, a start anywhere in the first stride, the horse's stride-to-stride
variation on) are recorded from the procedural horse's saddle, perfect and through an
IMU strap (2 cm/s drift, 5 mm noise, 10 % of frames dropped, yaw drift, tilt, angle
noise), and run through the estimator. Printed per gait: the worst time until the
hooves are fully in after the start (strides), and per compared rider channel the
lowest correlation, over the seeds, between the rider of the rebuilt horse and the
rider of the full horse frames, from then on. Then the same for gait changes.

    .venv/bin/python bench/bench_saddle_table.py [seeds]     # default 5 seeds (~1-2 min)
"""

from __future__ import annotations

import sys

from riderlive.horse import GAIT_TABLE, GAITS, Gait
from riderlive.horse.script import Segment, ShotScript
from riderlive.saddle.estimator import Model
from riderlive.saddle.synthetic import IMU_STRAP
from riderlive.saddle.trial import COMPARED, GaitCase, trial

CHANGES = [
    ("walk", "trot"),
    ("trot", "walk"),
    ("trot", "canter"),
    ("canter", "trot"),
    ("canter", "gallop"),
    ("gallop", "canter"),
    ("walk", "canter"),
    ("canter", "walk"),
    ("trot", "gallop"),
]


def steady(model: Model, seeds: int) -> None:
    print("| gait | sensor | lock, worst (strides) | " + " | ".join(f"`{c}`" for c in COMPARED) + " |")
    print("| --- | --- | --- |" + " --- |" * len(COMPARED))
    for gait in GAITS:
        for label, faults in (("perfect", None), ("IMU strap", IMU_STRAP)):
            worst, lows = 0.0, dict.fromkeys(COMPARED, 1.0)
            for seed in range(seeds):
                case = GaitCase.draw(gait, seed)
                run = case.run(10.0, faults, model)
                locked = run.locked_from(gait)
                if locked is None:
                    worst = float("inf")
                    continue
                hooves_in = locked + model.ease_time(case.stride_hz)
                worst = max(worst, (hooves_in - float(run.t[0])) * case.stride_hz)
                for channel, value in run.correlations(hooves_in).items():
                    lows[channel] = min(lows[channel], value)
            cells = " | ".join(f"{lows[c]:.3f}" for c in COMPARED)
            print(f"| {gait} | {label} | {worst:.2f} | {cells} |")


def changes(model: Model, seeds: int) -> None:
    print("\n| change | re-lock, worst (strides of the new gait) | lowest correlation after |")
    print("| --- | --- | --- |")
    change = 5.0
    for before, after in CHANGES:
        spec = GAIT_TABLE[Gait(after)]
        stride_hz = spec.frequency_at(spec.default_speed)
        worst, low = 0.0, 1.0
        for seed in range(seeds):
            script = ShotScript(
                seed=seed, segment=[Segment(gait=before, seconds=change), Segment(gait=after, seconds=6)]
            )
            run = trial(script, 120.0, start=0.2, imperfections=IMU_STRAP, seed=seed, model=model)
            locked = run.locked_from(after, after=change)
            if locked is None:
                worst = float("inf")
                continue
            hooves_in = locked + model.ease_time(stride_hz)
            worst = max(worst, (hooves_in - change) * stride_hz)
            low = min(low, *run.correlations(hooves_in).values())
        print(f"| {before} -> {after} | {worst:.2f} | {low:.3f} |")


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    model = Model()
    steady(model, seeds)
    changes(model, seeds)


if __name__ == "__main__":
    main()
