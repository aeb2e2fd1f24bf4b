"""Default rider and horse skeletons, posed from the channels (for engines and the page).

- :func:`hello_skeletons`: both skeletons and their rigs as JSON-ready data (the
  service sends it in its hello; the page poses its 3D view from it).
- :func:`bone_quaternions`: the rider's per-bone local rotations ``(x, y, z, w)``,
  flattened, for a rider frame in ``channels.RIDER`` order.
- :func:`rider_pose`, :func:`horse_pose`: full poses (local and world transforms);
  ``rider_pose(values, tack=True)`` also reads the rider parts (reins, stirrups).

Axis convention: :data:`riderlive.skeleton.rig.AXES`; details in ``docs/skeleton.md``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.skeleton.horse import HORSE_NEUTRAL, HORSE_RIG
from riderlive.skeleton.rider import HUMANOID, rider_rig
from riderlive.skeleton.rig import AXES, Pose, Rig, solve

SKELETON_VERSION = 1
"""Bumped when bones are renamed or reordered (appending keeps the version)."""

__all__ = [
    "AXES",
    "HORSE_NEUTRAL",
    "HORSE_RIG",
    "HUMANOID",
    "SKELETON_VERSION",
    "Pose",
    "Rig",
    "bone_quaternions",
    "hello_skeletons",
    "horse_pose",
    "rider_pose",
    "rider_rig",
    "solve",
]


def _as_mapping(values: Sequence[float] | Mapping[str, float], names: tuple[str, ...]) -> Mapping[str, float]:
    if isinstance(values, Mapping):
        return values
    if len(values) != len(names):
        raise ValueError(f"expected {len(names)} values in channel order, got {len(values)}")
    return dict(zip(names, values, strict=True))


def rider_pose(values: Sequence[float] | Mapping[str, float], tack: bool = False) -> Pose:
    """The rider posed by a rider frame (``channels.RIDER`` order, or a name -> value map).

    ``tack``: pose with :func:`rider_rig` ``(tack=True)``, which also reads the rider parts
    (``channels.RIDER_PARTS``, by name in a map): hands on the reins, feet in the stirrups.
    """
    return solve(rider_rig(tack), _as_mapping(values, RIDER_NAMES))


def horse_pose(values: Sequence[float] | Mapping[str, float]) -> Pose:
    """The horse posed by a horse frame (``channels.HORSE`` order, or a name -> value map)."""
    return solve(HORSE_RIG, _as_mapping(values, HORSE_NAMES))


def bone_quaternions(rider_values: Sequence[float] | Mapping[str, float]) -> list[float]:
    """Local rotations of the rider's bones, ``x, y, z, w`` per bone in skeleton order."""
    return [c for q in rider_pose(rider_values).local_rotations for c in q]


def _with_bind_pose(rig: Rig) -> dict[str, Any]:
    """The rig's JSON, each bone with its bind (rest) pose: rotation identity, position in the skeleton frame."""
    data = rig.to_json()
    for bone, position in zip(data["bones"], rig.rest_world(), strict=True):
        bone["rest_rotation"] = [0.0, 0.0, 0.0, 1.0]
        bone["rest_position"] = list(position)
    return data


def hello_skeletons() -> dict[str, Any]:
    """Both skeletons, their rigs and the humanoid mapping, ready for ``json.dumps``."""
    rider = _with_bind_pose(rider_rig())
    for bone in rider["bones"]:
        unity, vrm = HUMANOID.get(bone["name"], (None, None))
        bone["unity"] = unity
        bone["vrm"] = vrm
    tack = _with_bind_pose(rider_rig(tack=True))
    for bone, named in zip(tack["bones"], rider["bones"], strict=True):
        bone["unity"], bone["vrm"] = named["unity"], named["vrm"]
    return {
        "version": SKELETON_VERSION,
        "axes": dict(AXES),
        "rider": rider,
        "rider_tack": tack,
        "horse": _with_bind_pose(HORSE_RIG),
        "attach": {"rider_root": "horse.saddle"},
        "bone_quaternions": {"skeleton": "rider", "layout": "x, y, z, w per bone, in rider bone order"},
    }
