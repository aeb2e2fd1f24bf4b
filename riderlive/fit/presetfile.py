"""Writing a fitted preset (the I/O edge): a TOML file ``bake``, ``serve`` and the page load like any other.

Every table of :class:`~riderlive.rules.params.RuleParams` is written in full, so the file
does not depend on the defaults of the version that wrote it. A comment block on top holds
the provenance: the starting preset, each take pair with its sha256 and the clock offset
applied, and the fit's figures; each fitted number carries its uncertainty in a comment,
each number the takes did not identify says so (it is the starting preset's value).
"""

from __future__ import annotations

import re
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from riderlive.configfile import validate
from riderlive.framefile import atomic_path
from riderlive.names import NAME_PATTERN
from riderlive.rules.params import RuleParams


def preset_name(path: str) -> str:
    """A preset name from an output path's stem (characters outside the name pattern become ``_``)."""
    name = re.sub(r"[^A-Za-z0-9_-]", "_", Path(path).stem)[:64]
    return name if re.fullmatch(NAME_PATTERN, name) else f"fit_{name}"[:64]


def _value(v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(float(v))


def render(preset: RuleParams, report: dict[str, Any], name: str) -> str:
    """The TOML text of ``preset`` named ``name`` with the provenance of ``report`` (see the module docstring)."""
    by_name = {p["name"]: p for p in report["parameters"]}
    lines = [
        f"# Fitted by `riderlive fit` at {datetime.now(UTC).strftime('%Y-%m-%dT%H:%M:%SZ')} from preset "
        f"{report['start']!r} (docs/fit.md).",
        f"# {report['residuals']} residuals, cost {report['cost']:.6g}, {report['iterations']} iterations, "
        f"{report['seconds']:.2f} s" + ("; translation drift removed" if report["drift_removed"] else "") + ".",
        "# takes (horse + rider, sha256; clock offset applied, rider + offset = horse):",
    ]
    for take in report["takes"]:
        rs = [c["r"] for c in take["channels"] if c["r"] is not None]
        lines.append(f"#   {take['horse']} sha256:{take['horse_sha256']}")
        lines.append(f"#   + {take['rider']} sha256:{take['rider_sha256']}")
        lines.append(
            f"#     offset {take['offset_s'] * 1000:+.3f} ms, {take['frames_used']} frames"
            + (f", r min {min(rs):.4f}" if rs else "")
        )
    identified = sum(p["identified"] for p in report["parameters"])
    lines.append(
        f"# {identified} of {len(report['parameters'])} numbers identified; held (not fitted): "
        + ", ".join(report["held_groups"])
    )
    description = f"Fitted from {len(report['takes'])} take(s), starting from {report['start']}."
    lines += ["", f"name = {_value(name)}", f"description = {_value(description)}"]
    for group, table in preset.model_dump().items():
        if not isinstance(table, dict):
            continue
        lines += ["", f"[{group}]"]
        for key, value in table.items():
            entry = by_name.get(f"{group}.{key}")
            comment = ""
            if entry is not None:
                if entry["uncertainty"] is not None:
                    tag = "identified" if entry["identified"] else "fitted in a group"
                    comment = f"  # {tag} +- {entry['uncertainty']:.2g}"
                else:
                    comment = "  # not identified: the starting preset's value"
            lines.append(f"{key} = {_value(value)}{comment}")
    return "\n".join(lines) + "\n"


def write(path: str, preset: RuleParams, report: dict[str, Any], name: str | None = None) -> None:
    """Write ``preset`` to ``path`` atomically (checked to load back equal first)."""
    name = name or preset_name(path)
    text = render(preset, report, name)
    import tomllib

    loaded = validate(RuleParams, tomllib.loads(text), path)
    if loaded.model_copy(update={"name": preset.name, "description": preset.description}) != preset:
        raise ValueError(f"{path}: the written preset would not load back equal")  # pragma: no cover
    with atomic_path(path) as tmp:
        tmp.write_text(text)
