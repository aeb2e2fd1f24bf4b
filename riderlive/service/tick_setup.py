"""The tick's setup from the service's config: what the web process starts a tick with.

Pure but for the clock it reads once (the engine's ``start``): :func:`make_setup` turns a
validated :class:`~riderlive.service.config.ServiceConfig` (its ``[input]``, ``[source]``,
``[tick]``, ``[rig]``, ``[guardian]``, ``[physics]`` and ``[saddle]`` sections) into the
picklable :class:`~riderlive.realtime.setup.TickSetup` the tick process is spawned with.
"""

from __future__ import annotations

import time

from riderlive.channels import RIDER_NAMES
from riderlive.devices.registry import DeviceSpec
from riderlive.realtime.core import Mode, Timing
from riderlive.realtime.record import RecordLayout
from riderlive.realtime.setup import TickSetup
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.params import RuleParams
from riderlive.service.config import ServiceConfig


def make_setup(
    config: ServiceConfig,
    params: RuleParams,
    layout: RecordLayout | None = None,
    devices: tuple[DeviceSpec, ...] = (),
) -> TickSetup:
    """The tick's setup from the service's config: timing, the rider's bounds (in the service's
    length unit, ``tick.length_scale`` per m), source, devices, guardian, physics, the record
    ``layout`` (default: no extra channels); ``start`` is now (``perf_counter`` s)."""
    source = config.source
    timing = Timing(
        delay=config.input.delay,
        hold=config.input.hold,
        ease_time=config.input.ease_time,
        blend_time=config.input.blend_time,
        resume_after=source.resume_after,
        fallback_procedural=source.fallback_procedural,
        param_blend=config.tick.param_blend_time,
    )
    low, high = config.ranges.ranges().limits(RIDER_NAMES, config.tick.length_scale)
    return TickSetup(
        rate=config.tick.rate,
        start=time.perf_counter(),
        timing=timing,
        params=params,
        animator=AnimatorLayer(),
        length_scale=config.tick.length_scale,
        gait=source.gait,
        speed=source.speed,
        seed=source.seed,
        terrain=source.terrain,
        mode=Mode.PROCEDURAL if source.kind == "procedural" else Mode.INPUT,
        realtime_priority=config.tick.realtime_priority,
        isolation=config.tick.isolation,
        spin=config.tick.spin,
        devices=devices,
        park_timeout=config.rig.park_timeout,
        arm_on_start="serve --arm" if config.rig.arm else None,
        guardian=bool(devices) and config.guardian.enabled,
        tail=config.physics.tail,
        physics_file=config.physics.file,
        layout=RecordLayout() if layout is None else layout,
        rider_bounds=(tuple(low), tuple(high)),
        saddle_point=config.saddle,
        phase_lock=config.tick.phase_lock,
        phase_margin=config.tick.phase_margin,
        spare=config.tick.spare,
        spare_nice=config.tick.spare_nice,
    )
