"""Loading TOML configuration into typed, validated models.

Every error names the file, the key (dotted path) and what was allowed, so a TD can
fix a preset or a rig map without reading code.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, TypeVar

import pydantic

ModelT = TypeVar("ModelT", bound=pydantic.BaseModel)

_PACKAGE = Path(__file__).resolve().parent
CONFIG_DIR = next(
    (d for d in (_PACKAGE / "_config", _PACKAGE.parent / "config") if d.is_dir()),
    _PACKAGE.parent / "config",
)
"""The shipped ``config/`` tree: in the repository, or copied into a wheel."""


class ConfigError(ValueError):
    """A configuration file that cannot be used; the message names file and key."""

    def __init__(self, source: str, key: str, message: str) -> None:
        self.source = source
        self.key = key
        self.message = message
        where = f"{source}: {key}" if key else source
        super().__init__(f"{where}: {message}")


class StrictModel(pydantic.BaseModel):
    """Base for config models: unknown keys and non-finite numbers are errors."""

    model_config = pydantic.ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file, turning syntax errors into :class:`ConfigError`."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(str(path), "", "file not found") from None
    except IsADirectoryError:
        raise ConfigError(str(path), "", "is a directory, not a file") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(str(path), "", f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise ConfigError(str(path), "", f"cannot be read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(path), "", f"not valid TOML: {exc}") from None


def validate(model: type[ModelT], data: Any, source: str) -> ModelT:
    """Validate ``data`` against ``model``; the first error becomes a ConfigError."""
    try:
        return model.model_validate(data)
    except pydantic.ValidationError as exc:
        err = exc.errors()[0]
        key = ".".join(str(part) for part in err["loc"])
        message = err["msg"]
        if err["type"] == "extra_forbidden":
            message = "unknown key"
        elif err["type"] == "finite_number":
            message = "must be a finite number (not NaN or inf)"
        if "input" in err and err["type"] != "extra_forbidden" and not isinstance(err["input"], dict):
            message = f"{message} (got {err['input']!r})"
        raise ConfigError(source, key, message) from None


def load(model: type[ModelT], path: str | Path) -> ModelT:
    """Read and validate one TOML file."""
    return validate(model, read_toml(path), str(path))
