"""Small takes for the export tests, written as the service's recorder writes them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import orjson
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.export import TakePoses, load_take
from riderlive.horse import DEFAULT_SCALE, generate_gait
from riderlive.rules import RiderModel
from riderlive.takes.recorder import TakeRecorder


def write_take(directory: Path, name: str, seconds: float = 1.0, rate: float = 120.0) -> Path:
    """A canter take (horse and rider) of ``seconds``, recorded row by row, closed."""
    horse = generate_gait("canter", seconds, rate, seed=3)
    frames = np.column_stack([horse.column(n) for n in HORSE_NAMES])
    rider = RiderModel(scale=DEFAULT_SCALE).evaluate_batch(frames)
    recorder = TakeRecorder(directory / f"{name}.csv", meta={"tick_rate": rate, "length_scale": 25.0})
    for k in range(len(frames)):
        recorder.add(10.0 + k / rate, frames[k], rider[k])
    recorder.close()
    return directory / f"{name}.csv"


@pytest.fixture(scope="session")
def take_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_take(tmp_path_factory.mktemp("takes"), "canter")


@pytest.fixture(scope="session")
def take(take_file: Path) -> TakePoses:
    return load_take(take_file)


def world(track_root_pos: np.ndarray, track_root_rot: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Skeleton positions (B, 3) placed by a root pose, in skeleton axes."""
    from riderlive.skeleton import quat

    q = tuple(track_root_rot)
    return np.array([np.add(track_root_pos, quat.rotate(q, tuple(p))) for p in positions])  # type: ignore[arg-type]


def sidecar(path: Path) -> dict[str, object]:
    return dict(orjson.loads(path.with_suffix(".json").read_bytes()))


__all__ = ["HORSE_NAMES", "RIDER_NAMES", "sidecar", "world", "write_take"]
