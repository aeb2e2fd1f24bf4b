"""Takes: the service's recordings of input and output frames, and their replay."""

from riderlive.takes.recorder import TakeRecorder, list_takes, replay_path, take_path
from riderlive.takes.replay import load_replay

__all__ = ["TakeRecorder", "list_takes", "load_replay", "replay_path", "take_path"]
