"""What a fit found, as figures: per take and channel (r, RMS), per parameter (value, uncertainty, status).

:func:`build` turns a :class:`~riderlive.fit.solve.Solution` into a plain dict (the
``--report`` JSON); :func:`text` prints it for a terminal. RMS is in degrees for rotations,
metres for translations (from the take's length unit), attribute units for hair and cloth;
r is Pearson's correlation of the fitted prediction with the rider take over the frames
used (None where either is constant). With ``drift`` on, translation channels are compared
after their offset and trend are taken out, as the fit compares them.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from riderlive.channels import Kind, lookup
from riderlive.fit.identify import Status
from riderlive.fit.problem import Aligned, predict
from riderlive.fit.solve import Solution
from riderlive.fit.vector import HELD_GROUPS
from riderlive.frameunits import METRES

FloatArray = npt.NDArray[np.float64]


def _unit(name: str) -> str:
    kind = lookup(name).kind
    return "deg" if kind is Kind.ROTATION else "m" if kind is Kind.TRANSLATION else "attribute"


def _correlation(x: FloatArray, y: FloatArray) -> float | None:
    if len(x) < 3:
        return None
    x, y = x - x.mean(), y - y.mean()
    denominator = math.sqrt(float(x @ x) * float(y @ y))
    if denominator <= 1e-12 * max(1.0, float(np.abs(y).max(initial=0.0))) ** 2:
        return None
    return float(x @ y) / denominator


def channel_figures(aligned: Aligned, preset: Any) -> list[dict[str, Any]]:
    """Per channel of ``aligned``: frames used, r and RMS of ``preset``'s prediction (see the module docstring)."""
    predicted = predict(aligned, preset)
    measured = aligned.pair.rider.values
    out = []
    for c, name in enumerate(aligned.channels):
        rows = aligned.valid[:, c]
        p, m = predicted[rows, c], measured[rows, c]
        q = aligned.projections.get(c)
        if q is not None:
            p, m = p - q @ (q.T @ p), m - q @ (q.T @ m)
        to_unit = aligned.pair.horse.scale / METRES if lookup(name).kind is Kind.TRANSLATION else 1.0
        rms = float(np.sqrt(np.mean((p - m) ** 2))) * to_unit if len(p) else None
        out.append(
            {"channel": name, "unit": _unit(name), "frames": int(rows.sum()), "r": _correlation(p, m), "rms": rms}
        )
    return out


def build(solution: Solution, notes: list[str] | None = None) -> dict[str, Any]:
    """The report of ``solution`` as JSON-ready data."""
    takes = []
    for aligned in solution.aligned:
        pair = aligned.pair
        takes.append(
            {
                "horse": pair.horse.name,
                "horse_sha256": pair.horse.sha256,
                "rider": pair.rider.name,
                "rider_sha256": pair.rider.sha256,
                "offset_s": aligned.offset,
                "frames": len(pair.rider.t),
                "frames_used": int(aligned.valid.any(axis=1).sum()),
                "channels": channel_figures(aligned, solution.preset),
            }
        )
    parameters = []
    ident = solution.identification
    for k, p in enumerate(solution.params):
        sigma = solution.sigma[k]
        parameters.append(
            {
                "name": p.name,
                "kind": p.kind.value,
                "start": float(solution.start_values[k]),
                "value": float(solution.values[k]),
                "uncertainty": None if math.isnan(sigma) else float(sigma),
                "identified": ident.status[k] is Status.IDENTIFIED,
                "status": ident.status[k].value,
                "confounded_with": [solution.params[g].name for g in ident.groups[k]],
            }
        )
    return {
        "start": solution.start.name,
        "drift_removed": any(a.drift for a in solution.aligned),
        "cost": solution.cost,
        "residuals": solution.rows,
        "iterations": solution.iterations,
        "seconds": solution.seconds,
        "held_groups": list(HELD_GROUPS),
        "notes": list(notes or ()),
        "takes": takes,
        "parameters": parameters,
    }


def _f(value: float | None, spec: str = ".4g") -> str:
    return "-" if value is None else format(value, spec)


def text(report: dict[str, Any]) -> str:
    """``report`` for a terminal: per take and channel, then per parameter."""
    lines = [
        f"fit from {report['start']}: {report['residuals']} residuals, cost {report['cost']:.6g}, "
        f"{report['iterations']} iterations, {report['seconds']:.2f} s"
        + (" (translation drift removed)" if report["drift_removed"] else ""),
        *(f"note: {n}" for n in report["notes"]),
    ]
    for take in report["takes"]:
        lines.append(
            f"\n{take['horse']} + {take['rider']}: offset {take['offset_s'] * 1000:+.2f} ms applied "
            f"(rider + offset = horse), {take['frames_used']}/{take['frames']} frames used"
        )
        lines.append(f"  {'channel':16s} {'r':>8s} {'rms':>10s} unit")
        for ch in take["channels"]:
            lines.append(f"  {ch['channel']:16s} {_f(ch['r'], '.5f'):>8s} {_f(ch['rms'], '.3g'):>10s} {ch['unit']}")
    lines.append(f"\n{'parameter':42s} {'start':>10s} {'value':>12s} {'+-':>9s}  status")
    for p in report["parameters"]:
        status = p["status"] + (f" [{', '.join(p['confounded_with'])}]" if p["confounded_with"] else "")
        lines.append(f"{p['name']:42s} {p['start']:10.5g} {p['value']:12.6g} {_f(p['uncertainty'], '9.2g')}  {status}")
    lines.append(f"held at the starting preset (not fitted): {', '.join(report['held_groups'])}")
    return "\n".join(lines)


def plot(solution: Solution, path: str, channels: int = 9) -> None:
    """The first take's ``channels`` most moving channels: the rider, the fitted and the starting prediction."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    aligned = solution.aligned[0]
    fitted, started = predict(aligned, solution.preset), predict(aligned, solution.start)
    measured = aligned.pair.rider.values
    spread = [float(np.nanstd(np.where(aligned.valid[:, c], measured[:, c], np.nan))) for c in range(measured.shape[1])]
    order = np.argsort(spread)[::-1][:channels]
    fig, axes = plt.subplots(len(order), 1, figsize=(10, 1.6 * len(order)), sharex=True, squeeze=False)
    t = aligned.pair.rider.t
    for ax, c in zip(axes[:, 0], order, strict=True):
        rows = aligned.valid[:, c]
        ax.plot(t[rows], measured[rows, c], "k.", markersize=1.5, label="rider take")
        ax.plot(t, started[:, c], color="0.6", linewidth=0.8, label=f"start ({solution.start.name})")
        ax.plot(t, fitted[:, c], color="C1", linewidth=1.0, label="fitted")
        ax.set_ylabel(aligned.channels[c], fontsize=7)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel(f"s ({aligned.pair.rider.name}, offset {aligned.offset * 1000:+.1f} ms)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
