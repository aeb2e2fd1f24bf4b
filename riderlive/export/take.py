"""A take (or any frame file) as posed skeletons: the data every export format writes.

Reads through :func:`riderlive.framefile.read_frames` (so every frame-file format the
project reads), checks the take is complete and not being recorded, converts lengths
to metres and poses the horse and the rider for every frame at once
(:func:`riderlive.skeleton.rig.solve_frames`). The rider's root is its seat point on
the horse's ``saddle`` bone; with a horse in the take, ``rider_root`` carries the
saddle's world placement per frame, else it stays at the origin.
"""

from __future__ import annotations

import errno
import fcntl
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import orjson

from riderlive.channels import HORSE_NAMES, RIDER_NAMES, Kind, lookup
from riderlive.framefile import FrameFileError, FrameTable, read_frames
from riderlive.horse import DEFAULT_SCALE
from riderlive.skeleton import HORSE_RIG, rider_rig
from riderlive.skeleton.rig import PoseArrays, Rig, solve_frames
from riderlive.takes import take_path
from riderlive.takes.stamp import TakeTimecode, take_timecode
from riderlive.timecode import TimecodeError
from riderlive.units import metres_per_unit

FloatArray = npt.NDArray[np.float64]


class ExportError(ValueError):
    """A take that cannot be exported; the message says why and what to do."""


@dataclass(frozen=True)
class SkeletonTrack:
    """One skeleton over a take: its rig and its poses (metres, skeleton axes)."""

    rig: Rig
    poses: PoseArrays
    root_position: FloatArray
    """(N, 3): where the skeleton's origin is in the world, metres."""
    root_rotation: FloatArray
    """(N, 4): its world orientation, x y z w."""


@dataclass(frozen=True)
class TakePoses:
    name: str
    t: FloatArray
    """(N,) seconds from the first frame, ``k / rate``: frames are resampled (linearly, on the
    channels) onto a uniform grid when the take skipped ticks (BVH needs one frame time)."""
    rate: float
    """Frames per second: the take's tick rate (sidecar), or 1 / its median frame step."""
    horse: SkeletonTrack | None
    rider: SkeletonTrack | None
    ignored: tuple[str, ...]
    """Known channels that pose neither skeleton (``hair.*``, ``tail_NN.*``...)."""
    timecode: TakeTimecode | None = None
    """The label of the first frame (sidecar), None for a take from before timecode."""
    values: dict[str, FloatArray] = field(default_factory=dict)
    """The horse and rider channels that pose the skeletons, metres and degrees, on the grid ``t``."""

    @property
    def horse_channels(self) -> tuple[str, ...]:
        return HORSE_NAMES if self.horse is not None else ()

    @property
    def rider_channels(self) -> tuple[str, ...]:
        return RIDER_NAMES if self.rider is not None else ()

    def matrix(self, names: tuple[str, ...]) -> FloatArray:
        """(N, len(names)) of those channels."""
        return np.stack([self.values[n] for n in names], axis=1) if names else np.zeros((len(self.t), 0))


def timecode_fields(take: TakePoses) -> dict[str, str]:
    """The take's start timecode for a file's metadata (glTF ``extras``, the BVH export's
    sidecar, MCAP's metadata): ``timecode``, ``timecode_rate``, ``timecode_source``; {} when none."""
    return {} if take.timecode is None else take.timecode.as_meta()


def resolve_take(take: str, directory: str | Path) -> Path:
    """A take name in ``directory`` (``takes/NAME.csv``) or a path to a frame file."""
    as_path = Path(take)
    if as_path.suffix and (as_path.is_file() or os.sep in take):
        return as_path
    try:
        return take_path(directory, take)
    except ValueError as exc:
        raise ExportError(str(exc)) from None


def check_not_recording(path: Path) -> None:
    """Refuse a take the service is still writing (its recorder holds an exclusive lock)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        raise ExportError(f"{path}: no such take") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
            raise ExportError(f"{path}: the take is still being recorded; stop the recording first") from None
        raise
    finally:
        os.close(fd)


def sidecar_of(path: Path) -> dict[str, object]:
    meta = path.with_suffix(".json")
    if not meta.is_file():
        return {}
    try:
        data = orjson.loads(meta.read_bytes())
    except orjson.JSONDecodeError:
        return {}
    return data if isinstance(data, dict) else {}


def _complete(path: Path, table: FrameTable, names: tuple[str, ...], what: str) -> bool:
    present = [n for n in names if n in table.names]
    if present and len(present) != len(names):
        missing = [n for n in names if n not in table.names]
        raise ExportError(f"{path}: the take has some {what} channels but lacks {', '.join(missing[:5])}")
    return bool(present)


def load_take(path: Path, length_scale: float | None = None, rate: float | None = None) -> TakePoses:
    """Read, check and pose a take. ``length_scale``: thesis units per take length unit
    (default: the take's sidecar, else 25 = metres)."""
    check_not_recording(path)
    try:
        table = read_frames(str(path))
    except FrameFileError as exc:
        raise ExportError(str(exc)) from None
    if len(table) == 0:
        raise ExportError(f"{path}: the take has no frames")
    meta = sidecar_of(path)
    scale = float(length_scale or meta.get("length_scale") or DEFAULT_SCALE)  # type: ignore[arg-type]
    has_horse = _complete(path, table, HORSE_NAMES, "horse")
    has_rider = _complete(path, table, RIDER_NAMES, "rider")
    if not (has_horse or has_rider):
        raise ExportError(f"{path}: no horse or rider channels: nothing to export")
    used = set(HORSE_NAMES if has_horse else ()) | set(RIDER_NAMES if has_rider else ())
    ignored = tuple(n for n in table.names if n not in used)
    tick_rate = meta.get("tick_rate")
    t = table.times(float(tick_rate) if isinstance(tick_rate, int | float) else 120.0)
    if len(t) > 1 and not np.all(np.diff(t) > 0.0):
        raise ExportError(f"{path}: the take's times do not increase")
    if rate is None:
        if isinstance(tick_rate, int | float):
            rate = float(tick_rate)
        else:
            rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 120.0
    try:
        to_metres = metres_per_unit(scale)  # the one conversion, here at the file's edge
    except ValueError as exc:
        raise ExportError(f"{path}: {exc} (the take's length_scale)") from None
    grid = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * rate + 1e-6)) + 1) / rate
    uniform = len(grid) == len(t) and np.allclose(grid, t, rtol=0.0, atol=1e-6 / rate)

    def columns(names: tuple[str, ...]) -> dict[str, FloatArray]:
        """Metres and degrees on the uniform grid (linear between the take's frames)."""
        out = {}
        for name in names:
            column = table.column(name)
            if not uniform:
                column = np.interp(grid, t, column)
            out[name] = column * to_metres if lookup(name).kind is Kind.TRANSLATION else column
        return out

    try:
        stamp = take_timecode(meta)
    except TimecodeError as exc:
        raise ExportError(f"{path}: the sidecar's timecode is unusable: {exc}") from None
    n = len(grid)
    values: dict[str, FloatArray] = {}
    horse = rider = None
    saddle_pos = np.zeros((n, 3))
    saddle_rot = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    if has_horse:
        values |= columns(HORSE_NAMES)
        poses = solve_frames(HORSE_RIG, {name: values[name] for name in HORSE_NAMES}, n)
        horse = SkeletonTrack(HORSE_RIG, poses, np.zeros((n, 3)), saddle_rot.copy())
        saddle = HORSE_RIG.index["saddle"]
        saddle_pos = poses.world_positions[saddle]
        saddle_rot = poses.world_rotations[saddle]
    if has_rider:
        rig = rider_rig()
        values |= columns(RIDER_NAMES)
        poses = solve_frames(rig, {name: values[name] for name in RIDER_NAMES}, n)
        rider = SkeletonTrack(rig, poses, saddle_pos, saddle_rot)
    return TakePoses(path.stem, grid - grid[0], rate, horse, rider, ignored, stamp, values)
