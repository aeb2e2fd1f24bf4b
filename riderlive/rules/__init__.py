"""The rider rules: parameters, the equations, the engine and the animator layer."""

from __future__ import annotations

from riderlive.rules.engine import RiderModel
from riderlive.rules.params import RuleParams, load_preset

__all__ = ["RiderModel", "RuleParams", "load_preset"]
