"""REST for the page's take browser and weights panel: download, bake, parameter groups.

    GET  /api/takes/{name}/file      the take as recorded (CSV, or Parquet when only that exists)
    POST /api/takes/{name}/bake      {"preset": NAME | null, "format": "csv" | "parquet"}
                                     rules run over the take's horse -> ``baked/NAME.<format>``
    GET  /api/takes/{name}/baked     the last bake of the take
    GET  /api/params/groups          the rule parameters grouped by rule (with its equations)

A bake uses the service's current parameters and animator layer (what the page shows),
or a named preset; lengths stay in the take's unit (its sidecar's ``length_scale``), as
``riderlive bake`` does. Names are names (:data:`riderlive.names.NAME_PATTERN`), never
paths; an unknown take or preset is 404, the take being recorded is 409, a take the
rules cannot read is 422 saying why. One bake runs at a time (409 while one runs), in a
worker thread so the service keeps serving.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import pydantic
from fastapi import FastAPI, HTTPException
from fastapi import Path as PathParam
from fastapi.responses import FileResponse

from riderlive.bake import bake_table
from riderlive.configfile import ConfigError
from riderlive.framefile import FrameFileError, read_frames, write_frames
from riderlive.frameunits import resolve_scale
from riderlive.names import NAME_PATTERN
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.engine import RiderModel
from riderlive.rules.kuhnel2003 import RULE_INPUTS
from riderlive.rules.params import RuleParams, find_preset, load_preset
from riderlive.service.rest import Body, Name
from riderlive.takes.recorder import replay_path

if TYPE_CHECKING:
    from riderlive.service.runtime import Service

BAKED = "baked"
"""Subdirectory of the takes directory that holds the bakes (``NAME.csv`` / ``NAME.parquet``)."""
TakeName = Annotated[str, PathParam(min_length=1, max_length=64, pattern=NAME_PATTERN)]
MEDIA = {".csv": "text/csv", ".parquet": "application/vnd.apache.parquet"}


class BakeRequest(Body):
    preset: Name | None = None
    """None: the service's current parameters and animator layer."""
    format: Literal["csv", "parquet"] = "csv"


def param_groups(params: RuleParams) -> list[dict[str, Any]]:
    """``[{"group", "title", "keys"}]`` in preset order; ``title`` is the rule's docstring line (its equations)."""
    flat = params.flat()
    out = []
    for group, field in type(params).model_fields.items():
        annotation = field.annotation
        if not (isinstance(annotation, type) and issubclass(annotation, pydantic.BaseModel)):
            continue
        doc = (annotation.__doc__ or "").strip().splitlines()
        keys = [k for k in flat if k.startswith(f"{group}.")]
        out.append({"group": group, "title": doc[0] if doc else group, "keys": keys})
    return out


def _bake(source: Path, target: Path, params: RuleParams, service: Service, use_animator: bool) -> dict[str, Any]:
    table = read_frames(str(source))
    missing = [name for name in RULE_INPUTS if name not in table.names]
    if missing:
        raise FrameFileError(source.name, f"missing required channel(s): {', '.join(missing)}")
    scale, _ = resolve_scale(str(source), table, None)
    model = RiderModel(params=params, scale=scale, animator=service.animator if use_animator else AnimatorLayer())
    result = bake_table(table, model)
    target.parent.mkdir(parents=True, exist_ok=True)
    partial = target.with_name(f".partial-{target.name}")  # keeps the suffix that names the format
    write_frames(str(partial), result)
    partial.replace(target)
    return {"rows": len(result), "channels": list(result.names), "bytes": target.stat().st_size, "length_scale": scale}


def finished_take(service: Service, directory: Path, name: str) -> Path:
    """The file of take ``name`` in ``directory``: 404 when there is none, 409 while it is being recorded."""
    path = replay_path(directory, name)
    if not path.is_file():
        raise HTTPException(404, "no such take")
    recorder = service.recorder
    if recorder is not None and recorder.path == path:
        raise HTTPException(409, "that take is being recorded: stop it first")
    return path


def add_take_routes(app: FastAPI, service: Service, observe: list[Any]) -> None:
    directory = Path(service.config.takes.directory)
    preset_dirs = [Path(d) for d in service.config.tick.preset_dirs]
    busy = asyncio.Lock()

    def existing(name: str) -> Path:
        return finished_take(service, directory, name)

    def download(path: Path, name: str) -> FileResponse:
        return FileResponse(path, media_type=MEDIA.get(path.suffix, "application/octet-stream"), filename=name)

    @app.get("/api/takes/{name}/file", dependencies=observe, summary="Download a take as recorded")
    async def take_file(name: TakeName) -> FileResponse:
        path = existing(name)
        return download(path, path.name)

    @app.post("/api/takes/{name}/bake", summary="Bake a take's rider with the current rules")
    async def bake(name: TakeName, body: BakeRequest | None = None) -> dict[str, Any]:
        body = body or BakeRequest()
        source = existing(name)
        if body.preset is None:
            params, label = service.params, f"{service.params.name} (as set now)"
        else:
            found = find_preset(body.preset, preset_dirs)
            if found is None:
                raise HTTPException(404, f"no preset {body.preset!r}; GET /api/presets lists them")
            try:
                params, label = load_preset(found), body.preset
            except ConfigError:
                raise HTTPException(422, f"preset {body.preset!r} cannot be used (see the service log)") from None
        if busy.locked():
            raise HTTPException(409, "a bake is running: try again when it is done")
        target = directory / BAKED / f"{source.stem}.{body.format}"
        async with busy:
            for stale in (directory / BAKED).glob(f"{source.stem}.*"):
                stale.unlink(missing_ok=True)
            try:
                made = await asyncio.to_thread(_bake, source, target, params, service, body.preset is None)
            except (FrameFileError, ValueError) as exc:
                raise HTTPException(422, f"take {name!r} cannot be baked: {exc}") from None
        download_path = f"/api/takes/{name}/baked"
        return {"bake": {"take": name, "preset": label, "format": body.format, "download": download_path, **made}}

    @app.get("/api/takes/{name}/baked", dependencies=observe, summary="Download the last bake of a take")
    async def baked(name: TakeName) -> FileResponse:
        for suffix in MEDIA:
            path = directory / BAKED / f"{name}{suffix}"
            if path.is_file():
                return download(path, f"{name}.rider{suffix}")
        raise HTTPException(404, "that take has not been baked: POST /api/takes/NAME/bake")

    @app.get("/api/params/groups", dependencies=observe, summary="Rule parameters grouped by rule and equation")
    async def groups() -> dict[str, Any]:
        return {"groups": param_groups(service.params)}
