"""The motion platform's pure mechanism: geometry, inverse kinematics, motion cueing and the
safety stage, as Model / State / step (no I/O but reading a platform file, no clock).

The link, the device and the CLI in :mod:`riderlive.platform` use it; it uses none of them
but the firmware's vocabulary (``link_vocab``: the park the firmware does on its own).
"""
