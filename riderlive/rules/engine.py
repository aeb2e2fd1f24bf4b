"""The rider engine: horse frames in, rider frames out, one frame or a whole take.

A horse frame is a sequence of floats in the order of ``channels.HORSE``; a rider
frame is a sequence in the order of ``channels.RIDER``. Lengths come in the user's
units and are multiplied by ``scale`` into the thesis rig's units; translation
outputs are divided by ``scale`` on the way out. The animator layer (gain, offset)
applies in output units. Both paths evaluate the same rule source
(:mod:`riderlive.rules.kuhnel2003`): :meth:`RiderModel.evaluate` on floats, and
:meth:`RiderModel.evaluate_batch` either on NumPy arrays in cache-sized chunks or, from
:data:`COMPILED_FROM` frames, as the same scalar source compiled into a batch kernel
(:func:`riderlive.fastpath.batch`), which runs at the memory-traffic floor.

On sloping ground (``ground.rz`` not 0, thesis section 10) every path reads the horse
relative to the ground and adds the preset's ``[terrain]`` lean to ``lower_back.rz``
before the animator layer (:mod:`riderlive.rules.terrain`); a frame without the ground
channels, or with ``ground.rz`` 0, takes the flat path unchanged. Over a fence (the
forehand rising beyond any gait, hooves higher than a gallop lifts them) every path moves
the trunk and head toward the preset's ``[jump]`` pose (:mod:`riderlive.rules.jump`),
before the animator layer; outside a jump the rules' values pass untouched.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import astuple, dataclass, field

import numpy as np
import numpy.typing as npt

from riderlive import fastpath
from riderlive.channels import HORSE, HORSE_INDEX, RIDER, Kind
from riderlive.rules import jump as jump_layer
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.kuhnel2003 import ARRAY_OPS, RULE_INPUTS, SCALAR_OPS, RuleFunction, make_rules
from riderlive.rules.params import RuleParams
from riderlive.rules.terrain import GROUND_PITCH, LEAN_OUTPUT, PITCH_ARGUMENT, lean

FloatArray = npt.NDArray[np.float64]

_INPUT_COLUMNS: tuple[int, ...] = tuple(HORSE_INDEX[name] for name in RULE_INPUTS)
_INPUT_IS_LENGTH: tuple[bool, ...] = tuple(HORSE[HORSE_INDEX[name]].kind is Kind.TRANSLATION for name in RULE_INPUTS)
_PITCH, (_LF, _RF), (_LB, _RB) = jump_layer.PITCH, jump_layer.FRONT, jump_layer.BACK
_OUTPUT_IS_LENGTH: tuple[bool, ...] = tuple(c.kind is Kind.TRANSLATION for c in RIDER)
BATCH_CHUNK = 4096
"""Frames per chunk of the NumPy batch path: its temporaries stay in the CPU cache."""
COMPILED_FROM = 1_000_000
"""Takes of at least this many frames use the compiled batch kernel (when numba is installed). Its first
use with a preset compiles it (seconds; then cached on disk); shorter takes are as quick on NumPy."""


@dataclass(frozen=True)
class RiderModel:
    """Everything static about turning horse frames into rider frames."""

    params: RuleParams = field(default_factory=RuleParams)
    scale: float = 1.0
    animator: AnimatorLayer = field(default_factory=AnimatorLayer)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.scale) and self.scale > 0.0):
            raise ValueError(f"scale must be a finite number > 0, got {self.scale!r}")
        object.__setattr__(self, "_scalar", make_rules(self.params, SCALAR_OPS))
        object.__setattr__(self, "_array", make_rules(self.params, ARRAY_OPS))
        in_gain = tuple(self.scale if is_len else 1.0 for is_len in _INPUT_IS_LENGTH)
        out_scale = np.array([1.0 / self.scale if is_len else 1.0 for is_len in _OUTPUT_IS_LENGTH])
        gain = out_scale * self.animator.gain_vector()
        offset = self.animator.offset_vector()
        identity = bool(np.all(gain == 1.0) and np.all(offset == 0.0))
        object.__setattr__(self, "_in_gain", in_gain)
        object.__setattr__(self, "_in_gain_array", np.array(in_gain))
        object.__setattr__(self, "_unit_input", all(g == 1.0 for g in in_gain))
        object.__setattr__(self, "_out_gain", gain)
        object.__setattr__(self, "_out_offset", offset)
        pairs = None if identity else tuple(zip(gain.tolist(), offset.tolist(), strict=True))
        object.__setattr__(self, "_out_pairs", pairs)
        jp = self.params.jump
        object.__setattr__(self, "_jump_gate", (jp.pitch_from, jp.hooves_from) if jp.weight else None)

    def evaluate(self, horse: Sequence[float]) -> list[float]:
        """One frame on Python floats (the live tick's path)."""
        rules: RuleFunction = self._scalar  # type: ignore[attr-defined]
        if self._unit_input:  # type: ignore[attr-defined]
            args = [horse[i] for i in _INPUT_COLUMNS]
        else:
            args = [horse[i] * g for i, g in zip(_INPUT_COLUMNS, self._in_gain, strict=True)]  # type: ignore[attr-defined]
        ground = horse[GROUND_PITCH] if len(horse) > GROUND_PITCH else 0.0  # terrain.ground_pitch, inlined
        if ground:  # sloping ground: the rules read the horse relative to it, the rider leans
            args[PITCH_ARGUMENT] -= ground
            leaned = list(rules(*args))
            leaned[LEAN_OUTPUT] += lean(self.params.terrain, ground)
            out: Sequence[float] = leaned
        else:
            out = rules(*args)
        gate = self._jump_gate  # type: ignore[attr-defined]
        if gate is not None and (
            args[_PITCH] > gate[0] or args[_LF] + args[_RF] > gate[1] or args[_LB] + args[_RB] > gate[1]
        ):  # over a fence (rules/jump.py); else Appendix B's values pass untouched
            out = list(out)
            jump_layer.apply_scalar(self.params.jump, args, out)
        pairs = self._out_pairs  # type: ignore[attr-defined]
        if pairs is None:
            return list(out)
        return [v * g + o for v, (g, o) in zip(out, pairs, strict=True)]

    def evaluate_batch(self, horse: FloatArray, compiled: bool | None = None) -> FloatArray:
        """Many frames at once: ``horse`` is (N, len(HORSE)), the result (N, len(RIDER)).

        ``compiled``: the compiled kernel (True), NumPy chunks (False), or by take length (None).
        """
        horse = np.asarray(horse, dtype=np.float64)
        if horse.ndim != 2 or horse.shape[1] != len(HORSE):
            raise ValueError(f"expected an (N, {len(HORSE)}) array, got {horse.shape}")
        ground = horse[:, GROUND_PITCH]
        return self._batch([horse[:, i] for i in _INPUT_COLUMNS], horse.shape[0], compiled, ground)

    def evaluate_columns(
        self, columns: Mapping[str, FloatArray], frames: int, compiled: bool | None = None
    ) -> FloatArray:
        """:meth:`evaluate_batch` on named horse columns of ``frames`` values (absent channels are zero)."""
        zero = np.zeros(frames)
        ground = columns.get("ground.rz")
        return self._batch([columns.get(name, zero) for name in RULE_INPUTS], frames, compiled, ground)

    def _batch(
        self, inputs: list[FloatArray], n: int, compiled: bool | None, ground: FloatArray | None = None
    ) -> FloatArray:
        """The rules on ``inputs`` (RULE_INPUTS order) over ground pitch ``ground`` (deg; None: flat), then the
        terrain lean and the ``[jump]`` layer, in :meth:`evaluate`'s order; (N, len(RIDER)), each channel contiguous."""
        if ground is not None and ground.any():  # sloping ground somewhere (see the module docstring)
            ground = np.asarray(ground, dtype=np.float64)
            inputs = list(inputs)
            inputs[PITCH_ARGUMENT] = np.asarray(inputs[PITCH_ARGUMENT], dtype=np.float64) - ground
            out = self._rules(inputs, n, compiled)
            out[:, LEAN_OUTPUT] += self._out_gain[LEAN_OUTPUT] * lean(self.params.terrain, ground)  # type: ignore[attr-defined]
        else:
            out = self._rules(inputs, n, compiled)
        return self._jump(inputs, out)

    def _rules(self, inputs: list[FloatArray], n: int, compiled: bool | None) -> FloatArray:
        """Appendix B and the animator layer on ``inputs``: (N, len(RIDER)), each channel contiguous."""
        if compiled is None:
            compiled = fastpath.AVAILABLE and n >= COMPILED_FROM
        by_channel = np.empty((len(RIDER), n), dtype=np.float64)
        if compiled:
            if self._out_pairs is None:  # type: ignore[attr-defined]
                self._kernel()(inputs, by_channel, self._in_gain_array)  # type: ignore[attr-defined]
            else:
                gain, offset = self._out_gain, self._out_offset  # type: ignore[attr-defined]
                self._kernel()(inputs, by_channel, self._in_gain_array, gain, offset)  # type: ignore[attr-defined]
            return by_channel.T
        rules: RuleFunction = self._array  # type: ignore[attr-defined]
        in_gain = self._in_gain_array[:, None]  # type: ignore[attr-defined]
        for start in range(0, n, BATCH_CHUNK):
            stop = min(start + BATCH_CHUNK, n)
            columns = np.array([c[start:stop] for c in inputs], dtype=np.float64)
            if not self._unit_input:  # type: ignore[attr-defined]
                columns *= in_gain
            for row, column in zip(by_channel, rules(*columns), strict=True):
                row[start:stop] = column
        out = by_channel.T  # (N, C) view, column-major: each channel stays contiguous
        if self._out_pairs is not None:  # type: ignore[attr-defined]
            out *= self._out_gain  # type: ignore[attr-defined]
            out += self._out_offset  # type: ignore[attr-defined]
        return out

    def _jump(self, inputs: list[FloatArray], out: FloatArray) -> FloatArray:
        """The ``[jump]`` layer (rules/jump.py) on a batch's output, in place; frames outside a jump untouched."""
        if self.params.jump.weight:
            in_gain = self._in_gain  # type: ignore[attr-defined]
            args = [np.asarray(c, dtype=np.float64) * g for c, g in zip(inputs, in_gain, strict=True)]
            jump_layer.apply_columns(self.params.jump, args, out, self._out_gain, self._out_offset)  # type: ignore[attr-defined]
        return out

    def _kernel(self) -> fastpath.BatchKernel:
        """The compiled batch kernel of this preset's rules (built on first use)."""
        built: fastpath.BatchKernel | None = self.__dict__.get("_compiled")
        if built is None:
            rules = make_rules(self.params, SCALAR_OPS)
            built = fastpath.batch(rules, len(RULE_INPUTS), len(RIDER), helpers=astuple(SCALAR_OPS))
            object.__setattr__(self, "_compiled", built)
        return built
