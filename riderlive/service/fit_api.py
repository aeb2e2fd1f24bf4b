"""REST for "fit a preset" on the page: a take's reference rider, the fit, its report (docs/fit.md).

    PUT  /api/takes/{name}/reference?format=csv|jsonl|parquet|bvh[&bonemap=NAME][&length_scale=X]
                                  the file as the body -> ``takes/references/NAME.<format>``
    GET  /api/takes/{name}/reference   which rider a fit of the take would use
    POST /api/takes/{name}/fit    {"preset": NAME, "start": NAME | null, "reference": "uploaded" |
                                  "recorded" | null, "drift": false, "overwrite": false}

A take's reference rider is an uploaded rider take (checked as ``riderlive fit`` reads it
when uploaded: 422 saying why, nothing kept) or, failing that, the rider the take recorded
beside its horse. The references live in a subdirectory of the takes directory, so they
are never listed or replayed as takes. The fit runs in a child process
(:mod:`riderlive.service.fit_worker`, niced, killed after ``takes.fit_timeout`` s: 422),
one at a time (409 while one runs), and writes the preset ``NAME`` into the first of
``tick.preset_dirs`` (none configured: 409); ``PUT /api/preset`` then applies it with the
usual blend. A shipped preset's name, or an existing file without ``overwrite``, is 409.
Unknown take: 404; no reference rider: 404; takes the fit cannot use: 422 with the reason.
"""

from __future__ import annotations

import asyncio
import os
import sys
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import orjson
from fastapi import FastAPI, HTTPException, Query, Request

import riderlive
from riderlive.configfile import ConfigError
from riderlive.fit.problem import FitInputError
from riderlive.fit.takes import read_rider
from riderlive.framefile import FrameFileError
from riderlive.horse import DEFAULT_SCALE
from riderlive.names import NAME_PATTERN
from riderlive.rules.params import find_preset
from riderlive.service.fit_worker import FitJob
from riderlive.service.rest import Body, BodyTooLarge, Name
from riderlive.service.takes_api import TakeName, finished_take
from riderlive.takes.recorder import replay_path

if TYPE_CHECKING:
    from riderlive.service.runtime import Service

REFERENCES = "references"
"""Subdirectory of the takes directory holding the reference riders (``NAME.<format>``, ``NAME.json``)."""
REFERENCE_LIMIT = 256 * 1024 * 1024
"""Bytes of an uploaded reference rider (a 10 min 120 Hz CSV of every rider channel is ~100 MB)."""
REFERENCE_PATH = r"^/api/takes/[^/]+/reference$"
"""The upload route, for :class:`riderlive.service.rest.RestGuard`'s larger limit."""
FORMATS = ("csv", "jsonl", "parquet", "bvh")
PACKAGE_ROOT = str(Path(riderlive.__file__).resolve().parents[1])


class Reference(StrEnum):
    """Where a take's reference rider comes from."""

    UPLOADED = "uploaded"
    RECORDED = "recorded"


class FitRequest(Body):
    preset: Name
    """The name of the preset to write (into the first of ``tick.preset_dirs``)."""
    start: Name | None = None
    """The starting preset (its held groups and unidentified numbers stay); None: the current one."""
    reference: Reference | None = None
    """None: the uploaded reference if there is one, else the recorded rider."""
    drift: bool = False
    """Take out translation offsets and trends (mocap drift; docs/fit.md)."""
    overwrite: bool = False


def uploaded(directory: Path, name: str) -> Path | None:
    """The uploaded reference rider of take ``name``, if any."""
    return next((p for f in FORMATS if (p := directory / REFERENCES / f"{name}.{f}").is_file()), None)


def recorded_channels(path: Path) -> int:
    """How many rider channels take file ``path`` recorded (its header or Parquet schema only)."""
    from riderlive.channels import RIDER_INDEX

    try:
        if path.suffix == ".parquet":
            import polars as pl

            names = list(pl.read_parquet_schema(path))
        else:
            with path.open("rb") as fh:
                names = fh.readline(1 << 16).decode("utf-8", "replace").strip().split(",")
    except OSError:
        return 0
    except Exception:  # an unreadable Parquet footer: no recorded rider
        return 0
    return sum(n in RIDER_INDEX for n in names)


def reference_of(directory: Path, name: str) -> dict[str, Any] | None:
    """``{"source", "file"?, "bonemap"?, "channels"?}`` of take ``name``'s reference rider, or None."""
    path = uploaded(directory, name)
    if path is not None:
        try:
            meta = orjson.loads(path.with_suffix(".json").read_bytes())
        except (OSError, orjson.JSONDecodeError):
            meta = {}
        return {"source": Reference.UPLOADED.value, "file": path.name, **(meta if isinstance(meta, dict) else {})}
    take = replay_path(directory, name)
    count = recorded_channels(take) if take.is_file() else 0
    return {"source": Reference.RECORDED.value, "channels": count} if count else None


def with_references(takes: list[dict[str, object]], directory: str) -> list[dict[str, object]]:
    """``list_takes`` entries with their ``reference`` (None: nothing to fit against)."""
    folder = Path(directory)
    out = []
    for entry in takes:
        ref = reference_of(folder, str(entry["name"]))
        out.append({**entry, "reference": ref["source"] if ref else None})
    return out


def _check_upload(path: Path, fmt: str, bonemap: str | None) -> list[str]:
    """The rider channels ``riderlive fit`` would read from ``path`` (FitInputError etc. if none)."""
    rider, _ = read_rider(str(path), DEFAULT_SCALE, bonemap=bonemap if fmt == "bvh" else None)
    return list(rider.names)


def add_fit_routes(app: FastAPI, service: Service, observe: list[Any]) -> None:
    directory = Path(service.config.takes.directory)
    preset_dirs = [Path(d) for d in service.config.tick.preset_dirs]
    timeout = service.config.takes.fit_timeout
    busy = asyncio.Lock()

    def take_file(name: str) -> Path:
        return finished_take(service, directory, name)

    @app.get("/api/takes/{name}/reference", dependencies=observe, summary="A take's reference rider (for a fit)")
    async def get_reference(name: TakeName) -> dict[str, Any]:
        take_file(name)
        found = reference_of(directory, name)
        if found is None:
            raise HTTPException(404, "this take has no reference rider: PUT one, or record a take with its rider")
        return {"reference": found}

    @app.put("/api/takes/{name}/reference", summary="Upload a take's reference rider")
    async def put_reference(
        name: TakeName,
        request: Request,
        format: Annotated[Literal["csv", "jsonl", "parquet", "bvh"], Query()],
        bonemap: Annotated[str | None, Query(min_length=1, max_length=64, pattern=NAME_PATTERN)] = None,
        length_scale: Annotated[float | None, Query(gt=0.0, le=1e6, allow_inf_nan=False)] = None,
    ) -> dict[str, Any]:
        take_file(name)
        if bonemap is not None and format != "bvh":
            raise HTTPException(422, "bonemap is for a BVH reference only")
        if length_scale is not None and format == "bvh":
            raise HTTPException(422, "a BVH's lengths are in its bone map's unit: no length_scale")
        folder = directory / REFERENCES
        folder.mkdir(parents=True, exist_ok=True)
        partial = folder / f".upload-{name}.{format}"
        try:
            try:
                with partial.open("wb") as out:
                    async for chunk in request.stream():
                        out.write(chunk)
            except BodyTooLarge:
                raise HTTPException(413, f"a reference rider is at most {REFERENCE_LIMIT} bytes") from None
            if partial.stat().st_size == 0:
                raise HTTPException(422, "the body is empty: send the rider take's file")
            if length_scale is not None:  # read_rider converts lengths by the sidecar's unit
                partial.with_suffix(".json").write_bytes(orjson.dumps({"length_scale": length_scale}))
            try:
                channels = await asyncio.to_thread(_check_upload, partial, format, bonemap)
            except (FitInputError, FrameFileError, ConfigError, ValueError, OSError) as exc:
                reason = str(exc).replace(str(partial), "the upload")
                raise HTTPException(422, f"not a rider take riderlive fit can read: {reason}") from None
            meta = {"format": format, "bonemap": bonemap, "length_scale": length_scale, "channels": len(channels)}
            for stale in folder.glob(f"{name}.*"):
                stale.unlink(missing_ok=True)
            partial.with_suffix(".json").write_bytes(orjson.dumps(meta))
            partial.with_suffix(".json").replace(folder / f"{name}.json")
            partial.replace(folder / f"{name}.{format}")
        finally:
            partial.unlink(missing_ok=True)
            partial.with_suffix(".json").unlink(missing_ok=True)
        return {"reference": reference_of(directory, name)}

    @app.post("/api/takes/{name}/fit", summary="Fit a preset to a take's reference rider")
    async def fit_take(name: TakeName, body: FitRequest) -> dict[str, Any]:
        take = take_file(name)
        if busy.locked():  # first: a second fit is refused whatever it asks
            raise HTTPException(409, "a fit is running: try again when it is done")
        if not preset_dirs:
            raise HTTPException(409, "no directory to save a preset in: set tick.preset_dirs in the service config")
        if find_preset(body.preset) is not None:
            raise HTTPException(409, f"{body.preset!r} is a shipped preset's name: choose another")
        output = preset_dirs[0] / f"{body.preset}.toml"
        if output.exists() and not body.overwrite:
            raise HTTPException(409, f"preset {body.preset!r} exists: choose another name or overwrite")
        start_name = body.start or service.params.name
        start = find_preset(start_name, preset_dirs)
        if start is None:
            raise HTTPException(404, f"no preset {start_name!r} to start from; GET /api/presets lists them")
        rider: Path | None = uploaded(directory, name)
        if body.reference is Reference.RECORDED or (body.reference is None and rider is None):
            rider = None
            if not recorded_channels(take):
                raise HTTPException(404, "this take has no reference rider: PUT one, or record a take with its rider")
        elif rider is None:
            raise HTTPException(404, "this take has no uploaded reference rider: PUT /api/takes/NAME/reference")
        meta = reference_of(directory, name) or {}
        job = FitJob(
            horse=str(take),
            rider=None if rider is None else str(rider),
            bonemap=meta.get("bonemap") if rider is not None else None,
            start=str(start),
            output=str(output),
            name=body.preset,
            drift=body.drift,
        )
        async with busy:
            output.parent.mkdir(parents=True, exist_ok=True)
            code, out, err = await _run(job, timeout)
        err = err.replace(f"{directory}{os.sep}", "").replace(f"{preset_dirs[0]}{os.sep}", "")  # names, not paths
        if code == 2:
            raise HTTPException(422, f"take {name!r} cannot be fitted: {err}")
        if code != 0:
            raise HTTPException(422, f"the fit of {name!r} stopped: {err}")
        report = orjson.loads(out)
        report["reference"] = Reference.RECORDED.value if rider is None else Reference.UPLOADED.value
        return {"fit": report}


async def _run(job: FitJob, timeout: float) -> tuple[int, bytes, str]:
    """Run ``job`` in a child process: (exit status, stdout, last stderr line); killed after ``timeout`` s."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (PACKAGE_ROOT, os.environ.get("PYTHONPATH")) if p)}
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "riderlive.service.fit_worker",
        job.model_dump_json(),
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=env,
    )
    try:
        out, err = await asyncio.wait_for(proc.communicate(), timeout)
    except TimeoutError:
        return -1, b"", f"it took over {timeout:g} s (takes.fit_timeout): a shorter take fits sooner"
    finally:
        if proc.returncode is None:  # timed out, or the request was cancelled (the service stopping)
            proc.kill()
            await proc.wait()
    lines = err.decode("utf-8", "replace").strip().splitlines()
    assert proc.returncode is not None
    return proc.returncode, out, lines[-1] if lines else f"exit status {proc.returncode}"
