"""Motion platform speed: one tick (cueing + IK + safety) and a bake of a million frames.

    .venv/bin/python bench/bench_platform.py [--frames 1000000] [--platform stewart_linear]

Prints, per platform, the median time of one live tick (``riderlive.platform.step``:
cueing, inverse kinematics with the workspace check, the safety stage) on a trot, the
same for frames whose pose the workspace scale-back has to shrink (a jump), and the
ratio to a plain NumPy IK of one frame (rotation matrix, ``B + R p - b`` and norms
with NumPy arrays: the usual first implementation) measured in the same run. Then the
bake's throughput for N frames of saddle poses (compiled cueing and limits, chunked
array IK), warm (best of 3) and cold (the first call in the process, numba's disk
cache loaded). Pinned to one core. Then the device's whole tick without I/O
(``riderlive.platform.device``: ``pipeline.step``, cueing + IK + safety follower, and the
TARGET frame of ``plug_link.target_counts`` encoded for the link, COBS and CRC), against the same NumPy IK baseline.
Targets (issue 13): tick <= 50 us median (with the encode); bake >= 1 M frames/s at N = 1e6.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from riderlive.horse import generate, load_script
from riderlive.horse.script import gait_script
from riderlive.platform import PlatformModel, bake, initial, shipped_platforms, step
from riderlive.platform.link import Target, encode
from riderlive.platform.mechanism.geometry import Geometry
from riderlive.platform.plug_link import position_units, target_counts
from riderlive.platform.saddle_input import saddle_pose

RATE = 120.0


def numpy_ik(g: Geometry) -> Callable[[np.ndarray], np.ndarray]:
    """The baseline: one frame's leg lengths the obvious NumPy way."""
    base = np.asarray(g.base)
    joints = np.asarray(g.platform)

    def ik(pose: np.ndarray) -> np.ndarray:
        rx, ry, rz = np.radians(pose[3:])
        cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
        r = (
            np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
            @ np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
            @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        )
        legs = pose[:3] + joints @ r.T - base
        lengths: np.ndarray = np.linalg.norm(legs, axis=1)
        return lengths

    return ik


def numpy_ik_batch(g: Geometry) -> Callable[[np.ndarray], np.ndarray]:
    """The bake's baseline: every frame's leg lengths at once with plain NumPy (einsum, norm)."""
    base = np.asarray(g.base)
    joints = np.asarray(g.platform)

    def ik(poses: np.ndarray) -> np.ndarray:
        rx, ry, rz = np.radians(poses[:, 3:]).T
        cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
        r = np.empty((len(poses), 3, 3))
        r[:, 0] = np.stack([cy * cz, sy * sx - cy * sz * cx, cy * sz * sx + sy * cx], axis=1)
        r[:, 1] = np.stack([sz, cz * cx, -cz * sx], axis=1)
        r[:, 2] = np.stack([-sy * cz, sy * sz * cx + cy * sx, cy * cx - sy * sz * sx], axis=1)
        legs = poses[:, None, :3] + np.einsum("nij,lj->nli", r, joints) - base
        lengths: np.ndarray = np.linalg.norm(legs, axis=2)
        return lengths

    return ik


def tick_us(model: PlatformModel, saddle: np.ndarray, repeats: int = 5) -> float:
    """Median over ``repeats`` passes of the mean time per frame (us) of the live tick."""
    frames = saddle.tolist()
    samples = []
    for _ in range(repeats):
        state = initial(model)
        start = time.perf_counter()
        for frame in frames:
            state, _ = step(model, state, frame, 1.0 / RATE)
        samples.append((time.perf_counter() - start) / len(frames) * 1e6)
    return statistics.median(samples)


def device_tick_us(model: PlatformModel, saddle: np.ndarray, repeats: int = 5) -> float:
    """Median over ``repeats`` passes of the mean time per frame (us) of the plug's tick without I/O."""
    frames = saddle.tolist()
    units = position_units(model)
    samples = []
    for _ in range(repeats):
        state = initial(model)
        start = time.perf_counter()
        for seq, frame in enumerate(frames):
            state, out = step(model, state, frame, 1.0 / RATE)
            encode(Target(target_counts(out.positions, units)), seq & 0xFFFF)
        samples.append((time.perf_counter() - start) / len(frames) * 1e6)
    return statistics.median(samples)


def per_frame_us(fn: object, frames: np.ndarray, repeats: int = 5) -> float:
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for frame in frames:
            fn(frame)  # type: ignore[operator]
        samples.append((time.perf_counter() - start) / len(frames) * 1e6)
    return statistics.median(samples)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=1_000_000)
    parser.add_argument("--platform", action="append", help="platform(s) to measure (default: all shipped)")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})  # one core

    trot = saddle_pose(generate(gait_script("trot", 20.0), rate=RATE))
    jump = saddle_pose(generate(load_script("config/shots/jump.toml"), rate=RATE))
    names = args.platform or shipped_platforms()
    models = {name: PlatformModel.load(name) for name in names}
    cold_model = models[names[0]]
    start = time.perf_counter()
    bake(cold_model, trot[:1000], 1.0 / RATE)  # loads (or compiles) the kernels
    print(f"first bake in this process (kernels from numba's cache or compiled): {time.perf_counter() - start:.2f} s")

    for name, model in models.items():
        result = bake(model, jump, 1.0 / RATE)
        scaled = jump[result.scale < 1.0]
        ours = tick_us(model, trot)
        baseline = per_frame_us(numpy_ik(model.geometry), result.pose[:2000])
        print(f"{name}: tick {ours:.1f} us/frame median on a trot (target <= 50)")
        print(f"  baseline plain NumPy IK of one frame: {baseline:.1f} us; ratio tick/baseline = {ours / baseline:.2f}")
        whole = device_tick_us(model, trot)
        print(
            f"  device tick (cueing + IK + safety + TARGET encode): {whole:.1f} us/frame median (target <= 50); "
            f"ratio to the NumPy IK baseline = {whole / baseline:.2f}"
        )
        if len(scaled):
            state = initial(model)
            samples = []
            for frame in jump.tolist():
                t0 = time.perf_counter()
                state, out = step(model, state, frame, 1.0 / RATE)
                if out.aim.scale < 1.0:
                    samples.append((time.perf_counter() - t0) * 1e6)
            shrunk = statistics.median(samples)
            print(f"  frames the scale-back shrinks ({len(samples)} in the jump): {shrunk:.1f} us median")

    bake_name = "stewart_linear" if "stewart_linear" in models else names[0]  # six legs: the heavier bake
    model = models[bake_name]
    rng = np.random.default_rng(0)
    reps = -(-args.frames // len(trot))
    saddle = np.tile(trot, (reps, 1))[: args.frames] + rng.normal(0.0, 1e-4, (args.frames, 6))
    start = time.perf_counter()
    result = bake(model, saddle, 1.0 / RATE)
    cold = args.frames / (time.perf_counter() - start)
    warm, cpu = [], []
    for _ in range(3):
        start, start_cpu = time.perf_counter(), time.process_time()
        bake(model, saddle, 1.0 / RATE)
        warm.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    batch_baseline = numpy_ik_batch(model.geometry)
    base = []
    for _ in range(3):
        start = time.perf_counter()
        batch_baseline(result.pose)
        base.append(time.perf_counter() - start)
    print(
        f"bake {bake_name}, N={args.frames:,}, one core: {args.frames / min(warm) / 1e6:.2f} M frames/s warm "
        f"(best of 3; {args.frames / min(cpu) / 1e6:.2f} M/s of CPU time), {cold / 1e6:.2f} M frames/s first call "
        "(target >= 1)"
    )
    print(
        f"  baseline plain NumPy batch IK alone (einsum + norm): {args.frames / min(base) / 1e6:.2f} M frames/s; "
        f"ratio bake/baseline throughput = {min(base) / min(warm):.2f}"
    )


if __name__ == "__main__":
    main()
