"""Strand physics: the horse's tail (many strands, and one strand driving a bone chain) and the rider's braid.

Modules: :mod:`strands` (the solver: Model / State / step), :mod:`collision`
(capsules), :mod:`chain` (bone chains driven by strands), :mod:`vec3` (3-vector
helpers of the kernels), :mod:`quaternion`,
:mod:`attach` (dock, rider pose and colliders from horse and rider frames),
:mod:`reference` (the 400-strand tail), :mod:`skinned` (skinned tail + braid in one
state), :mod:`drive` (sources and the fixed-step accumulator), :mod:`outputs`
(``tail_NN`` / ``braid_NN`` channels), :mod:`config` (``config/physics/tail.toml``),
:mod:`cli` (``riderlive tail``), :mod:`compare` (skinned vs reference). See
``docs/tail.md``. The solver, posing and chains are written once, as loops, and
compiled with numba (:mod:`riderlive.fastpath`; cached on disk after the first run).

Live use (publishing stays outside the step)::

    model = SkinnedModel.build(load_physics())
    source = LiveSource(horse, rider_rules)          # horse.sample(t), RiderModel
    stepper = FixedStepper(model.step, model.initial(source(t0)), model.config.rate, start=t0, max_catch_up=48)
    names = channel_names(model)
    every tick:  stepper.advance_to(now, source); values = publish(model, stepper.state)
"""

from __future__ import annotations
