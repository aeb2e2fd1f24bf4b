"""How closely the skinned tail follows the reference: tip paths over a take, correlation, plot.

    python -m riderlive.physics.compare [OUT.png]

runs both tails on a procedural trot -> rear -> gallop take (240 Hz), expresses the
skinned chain's tip and the mean tip of the reference strands in the hindquarters
frame (so the horse's own travel does not inflate the agreement), prints Pearson r
per axis and the RMS distance, and writes a small plot.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.horse import ProceduralHorse
from riderlive.physics.attach import HINDQUARTERS
from riderlive.physics.config import PhysicsConfig
from riderlive.physics.drive import FixedStepper, Source, TakeSource
from riderlive.physics.reference import ReferenceModel, mean_tip
from riderlive.physics.skinned import TAIL, SkinnedModel

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class TipPaths:
    """Times (F,) and tip positions (F, 3) in the hindquarters frame, metres."""

    t: FloatArray
    skinned: FloatArray
    reference: FloatArray

    def correlation(self) -> FloatArray:
        """Pearson r per axis (x forward, y up, z side)."""
        return np.array([np.corrcoef(self.skinned[:, i], self.reference[:, i])[0, 1] for i in range(3)])

    def rms(self) -> float:
        return float(np.sqrt(np.mean(np.sum((self.skinned - self.reference) ** 2, axis=1))))


def trot_rear_gallop(rate: float = 240.0, rear_at: float = 2.0, gallop_at: float = 5.4, end: float = 8.0) -> TakeSource:
    """A procedural horse: trot, rear at ``rear_at``, gallop from ``gallop_at`` seconds."""
    horse = ProceduralHorse("trot")
    times = np.arange(round(end * rate) + 1) / rate
    frames = []
    for t in times:
        if abs(t - rear_at) < 0.5 / rate:
            horse.perform("rear")
        if abs(t - gallop_at) < 0.5 / rate:
            horse.set_gait("gallop")
        frames.append(horse.sample(float(t)))
    return TakeSource(times, np.array(frames))


def tip_paths(config: PhysicsConfig, source: Source, duration: float, sample_rate: float = 60.0) -> TipPaths:
    """Run both tails on ``source`` and sample their tips at ``sample_rate``."""
    ref, sk = ReferenceModel.build(config), SkinnedModel.build(config)
    r = FixedStepper(ref.step, ref.initial(source(0.0)), config.rate)
    s = FixedStepper(sk.step, sk.initial(source(0.0)), config.rate)
    times = np.arange(1, int(duration * sample_rate) + 1) / sample_rate
    a, b = [], []
    for t in times:
        r.advance_to(float(t), source)
        s.advance_to(float(t), source)
        hq = ref.body.pose(source(r.time).horse).frame(HINDQUARTERS)
        a.append(hq.rotation.T @ (s.state.strands.x[-1, :, TAIL] - hq.origin))
        b.append(hq.rotation.T @ (mean_tip(r.state) - hq.origin))
    return TipPaths(times, np.array(a), np.array(b))


def plot(paths: TipPaths, out: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(7.0, 4.6), sharex=True, dpi=80)
    r = paths.correlation()
    for i, (ax, name) in enumerate(zip(axes, ("x (forward)", "y (up)", "z (side)"), strict=True)):
        ax.plot(paths.t, paths.reference[:, i], color="0.55", lw=2.2, label="reference: mean tip of 400 strands")
        ax.plot(paths.t, paths.skinned[:, i], color="C3", lw=1.0, label="skinned chain: centre tip")
        ax.set_ylabel(f"{name}, m", fontsize=8)
        ax.text(0.99, 0.05, f"r = {r[i]:.3f}", transform=ax.transAxes, ha="right", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].legend(fontsize=7, loc="upper left", ncol=2)
    axes[-1].set_xlabel("time, s (trot; rear at 2 s; gallop from 5.4 s)", fontsize=8)
    fig.suptitle(f"Tail tip in the hindquarters frame; RMS distance {paths.rms() * 100:.1f} cm", fontsize=9)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    paths = tip_paths(PhysicsConfig(), trot_rear_gallop(), 8.0)
    r = paths.correlation()
    print(f"Pearson r x {r[0]:.3f}  y {r[1]:.3f}  z {r[2]:.3f}; RMS distance {paths.rms() * 100:.1f} cm")
    if args:
        plot(paths, args[0])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
