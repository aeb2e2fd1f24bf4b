"""Takes: the service's recordings of input and output frames, and their replay."""

from riderlive.takes.recorder import TakeExists, TakeRecorder, list_takes, recover_take, replay_path, take_path
from riderlive.takes.replay import load_replay

__all__ = ["TakeExists", "TakeRecorder", "list_takes", "load_replay", "recover_take", "replay_path", "take_path"]
