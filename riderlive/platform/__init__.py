"""The motion platform: saddle pose in, actuator commands out.

The pure mechanism, ``mechanism/``, from data to commands:

| module | owns |
| --- | --- |
| ``mechanism/geometry.py`` | the mechanism as numbers (joints, limits, home, park), frames and pose convention |
| ``mechanism/config.py`` | ``config/platforms/*.toml``: schema, validation, building a Geometry |
| ``mechanism/ik.py`` | inverse kinematics on floats and arrays, forward kinematics, workspace and scale-back |
| ``mechanism/cueing.py`` | replay and washout, tilt coordination, presets, live parameters (Model / State / step) |
| ``mechanism/limits.py`` | the safety stage (soft limits, speed, acceleration) and the eased soft start and park |
| ``mechanism/pipeline.py`` | cueing -> IK -> safety for one tick or a whole take |

Beside it, the I/O: ``cli.py`` (``riderlive platform``: bake a take to actuator tracks, plot
them, describe a platform), the serial link (``link*.py``, ``serial_link.py``), the device
(``device.py``, ``plug_*.py``) and the firmware's host build (``firmware_host.py``).
"""

from riderlive.platform.mechanism.config import PLATFORM_DIR, load_platform, shipped_platforms
from riderlive.platform.mechanism.geometry import POSE_AXES, Geometry, Kind
from riderlive.platform.mechanism.pipeline import Bake, PlatformModel, PlatformState, bake, initial, step

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
