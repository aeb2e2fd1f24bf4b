"""The tick's unit edges: the one place where the tick's lengths cross between metres and the service unit.

The tick's core (:class:`~riderlive.realtime.core.TickCore`) computes in the **service
length unit** (``tick.length_scale`` rig units per unit, ``length_scale / 25`` metres;
25: metres), because that is the unit of everything on either side of it: the input
ring (ingest converts each producer's ``length_scale`` to it, ``service/ingest.py``) and
the output record, which is the wire (``/ws/rider``, takes, NATS and VMC publish lengths in
the service unit: docs/protocol.md). A core in metres would convert every frame twice
(ring -> metres, metres -> record) and the rules a third time (they speak the thesis'
rig units behind their own adapter, ``RiderModel.scale``), so the core holds no unit and
the conversions sit here, built once from the configuration:

- **in**: the procedural horse speaks metres (:meth:`UnitEdges.procedural`); a saddle
  stream's samples go to the estimator in metres and its rebuilt horse comes back in the
  service unit (:meth:`UnitEdges.saddle_input`, ``realtime/saddle_input.py``);
- **physical quantities**: the saddle pose of the tick's horse at the configured point
  (metres; :meth:`UnitEdges.saddle`, for the record in the service unit), the rider parts
  on the skeletons' metres (:meth:`UnitEdges.rider_parts`);
- **the strands**: the tail physics (``realtime/tail.py``) speaks metres: the tick's horse
  and rider rows go in through :meth:`UnitEdges.strands_in`, the tail and braid channels
  come back to the service unit through :meth:`UnitEdges.strands_out` (a take replays
  through the same two to the bit);
- **out**: the devices' :class:`~riderlive.tickframe.TickFrame` in metres and degrees,
  built once per tick (``realtime/frame.frame_of`` with :attr:`UnitEdges.metres_per_unit`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from riderlive.realtime.saddle_input import SaddleInput, make_saddle_input, saddle_pose
from riderlive.rules.params import RuleParams
from riderlive.rules.parts import RiderParts
from riderlive.saddle.pose import SaddlePoint
from riderlive.units import HORSE_LENGTHS, RIDER_LENGTHS, metres_per_unit, units_per_metre

FloatArray = npt.NDArray[np.float64]
_HORSE_LENGTHS = list(HORSE_LENGTHS)
_RIDER_LENGTHS = list(RIDER_LENGTHS)


@dataclass(frozen=True)
class UnitEdges:
    """The tick's conversions for a service of ``length_scale`` rig units per length unit,
    its saddle at ``point`` (metres, in the horse's trunk frame)."""

    length_scale: float
    point: SaddlePoint = field(default_factory=SaddlePoint)
    metres_per_unit: float = field(init=False)
    """Metres per service length unit (``length_scale / 25``)."""
    _gain: float = field(init=False, repr=False)
    """Service units per metre, for the procedural horse (``25 / length_scale``: 1 exactly at 25)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "metres_per_unit", metres_per_unit(self.length_scale))
        object.__setattr__(self, "_gain", units_per_metre(self.length_scale))

    def procedural(self, frame: list[float]) -> list[float]:
        """A procedural horse frame (``channels.HORSE``, metres) in the service unit, in place."""
        gain = self._gain
        if gain != 1.0:
            for i in HORSE_LENGTHS:
                frame[i] *= gain
        return frame

    def saddle(self, horse: Sequence[float]) -> list[float]:
        """``channels.SADDLE`` of a horse frame at :attr:`point` (service unit in and out,
        degrees; computed in metres)."""
        return saddle_pose(horse, self.metres_per_unit, self.point)

    def saddle_input(self, delay: float) -> SaddleInput:
        """A saddle stream's input (service unit at the ring, metres in the estimator)."""
        return make_saddle_input(self.length_scale, self.point, delay)

    def rider_parts(self, params: RuleParams) -> RiderParts:
        """The rider parts of ``params`` for frames in the service unit (the skeletons speak metres)."""
        return RiderParts(params, self.metres_per_unit)

    def strands_in(self, horse: Sequence[float], rider: Sequence[float]) -> tuple[FloatArray, FloatArray]:
        """A tick's horse and rider rows (service unit, degrees) as the strands take them: new
        arrays in metres and degrees."""
        h = np.array(horse, dtype=np.float64)
        r = np.array(rider, dtype=np.float64)
        to_metres = self.metres_per_unit
        if to_metres != 1.0:
            h[_HORSE_LENGTHS] *= to_metres
            r[_RIDER_LENGTHS] *= to_metres
        return h, r

    def strands_out(self, values: FloatArray, lengths: npt.NDArray[np.bool_]) -> list[float]:
        """The strands' published channels (metres where ``lengths``, else degrees) in the
        service unit, as a list (``values`` is changed in place)."""
        to_metres = self.metres_per_unit
        if to_metres != 1.0:
            values[lengths] /= to_metres
        out: list[float] = values.tolist()
        return out
