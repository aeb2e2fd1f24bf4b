"""riderlive: a horse's motion in, a rider's reaction out, live.

The rider rules of Kuhnel (2003), a procedural horse, strand physics for tail and
braid, a fixed-rate service that publishes over websockets, and safe Dynamixel output.
"""

from __future__ import annotations

__version__ = "0.1.0"
