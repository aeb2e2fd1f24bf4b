"""The motion platform: saddle pose in, actuator commands out (the pure core and offline tools).

Modules, from data to commands:

| module | owns |
| --- | --- |
| ``geometry.py`` | the mechanism as numbers (joints, limits, home, park), frames and pose convention |
| ``config.py`` | ``config/platforms/*.toml``: schema, validation, building a Geometry |
| ``ik.py`` | inverse kinematics on floats and arrays, forward kinematics, workspace and scale-back |
| ``cueing.py`` | replay and washout, tilt coordination, presets, live parameters (Model / State / step) |
| ``limits.py`` | the safety stage (soft limits, speed, acceleration) and the eased soft start and park |
| ``pipeline.py`` | cueing -> IK -> safety for one tick or a whole take |
| ``cli.py`` | ``riderlive platform``: bake a take to actuator tracks, plot them, describe a platform |

The serial link (``link.py``) and the device lifecycle live beside these and use them.
"""

from riderlive.platform.config import PLATFORM_DIR, load_platform, shipped_platforms
from riderlive.platform.geometry import POSE_AXES, Geometry, Kind
from riderlive.platform.pipeline import Bake, PlatformModel, PlatformState, bake, initial, step

__all__ = [
    "PLATFORM_DIR",
    "POSE_AXES",
    "Bake",
    "Geometry",
    "Kind",
    "PlatformModel",
    "PlatformState",
    "bake",
    "initial",
    "load_platform",
    "shipped_platforms",
    "step",
]
