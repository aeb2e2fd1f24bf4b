"""The fit of ``POST /api/takes/{name}/fit`` in its own process (``python -m riderlive.service.fit_worker SPEC``).

The service runs this as a child process, niced, so a fit (seconds of numpy on a shared
core) never holds the web process's GIL and can be killed when it overruns its time.
``SPEC`` is a JSON object (:class:`FitJob`); the child reads the takes as ``riderlive
fit`` does (:mod:`riderlive.fit.takes`), fits, writes the preset atomically to
``output`` and prints the report (:func:`riderlive.fit.report.build`) as JSON on stdout.
Exit status 2 with one line on stderr when the takes cannot be used (the reason the
service answers with, 422); nothing is written then.
"""

from __future__ import annotations

import contextlib
import os
import sys

import orjson
import pydantic

from riderlive.configfile import ConfigError
from riderlive.fit.problem import FitInputError
from riderlive.framefile import FrameFileError

NICE = 10
"""Added to the child's niceness: the tick and the web process come first on a busy host."""


class FitJob(pydantic.BaseModel):
    """One fit: the take (its horse), its reference rider (None: the take's own rider columns)."""

    model_config = pydantic.ConfigDict(extra="forbid")
    horse: str
    rider: str | None = None
    bonemap: str | None = None
    start: str
    """The starting preset's file."""
    output: str
    """The preset file to write."""
    name: str
    """The preset's name (in the file)."""
    drift: bool = False


def run(job: FitJob) -> bytes:
    """Fit ``job``, write its preset, return the report as JSON."""
    from riderlive.fit import presetfile, report
    from riderlive.fit.problem import TakePair
    from riderlive.fit.solve import FitOptions, fit
    from riderlive.fit.takes import read_horse, read_recorded_rider, read_rider
    from riderlive.rules.params import load_preset

    start = load_preset(job.start)
    horse, notes = read_horse(job.horse)
    if job.rider is None:
        rider, rider_notes = read_recorded_rider(job.horse)
    else:
        rider, rider_notes = read_rider(job.rider, horse.scale, bonemap=job.bonemap)
    solution = fit([TakePair(horse, rider)], start, FitOptions(drift=job.drift))
    data = report.build(solution, notes + rider_notes)
    presetfile.write(job.output, solution.preset, data, job.name)
    data["preset"] = job.name
    return orjson.dumps(data, option=orjson.OPT_SERIALIZE_NUMPY)


def main(argv: list[str], nice: int = NICE) -> int:
    """Run the job in ``argv[1]`` at ``nice`` more niceness; the exit status (see the module docstring)."""
    with contextlib.suppress(OSError):  # a host that refuses: run at the service's priority
        os.nice(nice)
    try:
        job = FitJob.model_validate_json(argv[1])
        out = run(job)
    except (FitInputError, FrameFileError, ConfigError, ValueError, OSError) as exc:
        print(str(exc).replace("\n", " "), file=sys.stderr)
        return 2
    sys.stdout.buffer.write(out)
    return 0


if __name__ == "__main__":  # pragma: no cover - run as a child process by fit_api
    sys.exit(main(sys.argv))
