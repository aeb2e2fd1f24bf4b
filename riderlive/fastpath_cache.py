"""The disk cache of :func:`riderlive.fastpath.kernel`: fresh only while every source compiled in is unchanged.

numba's own cache watches the kernel's file alone; a helper in another file, or a module
constant, that changed would load stale machine code. :func:`cache_for` is numba's
``FunctionCache`` whose source stamp also covers :func:`sources_stamp`.

It uses numba internals (``Dispatcher._cache``, ``FunctionCache``, its ``_cache_file``'s
``_source_stamp``, ``load_overload`` / ``save_overload``): :func:`check_internals` fails
loudly, naming numba's version and the tested range, when they are not there.
"""

from __future__ import annotations

import hashlib
import inspect
import types
from collections.abc import Callable, Iterator
from functools import cache
from pathlib import Path
from typing import Any, cast

import numpy as np

COMPILE_FILES = tuple(
    str(Path(__file__).with_name(name)) for name in ("fastpath_core.py", "fastpath_batch.py", "fastpath_llvm.py")
)
"""The compile machinery's own files: in every stamp (a change to them may change the code generated)."""


TESTED = ((0, 68), (0, 68))
"""The numba minor versions this code is tested with (inclusive; ``pyproject.toml`` pins the same).
This module reaches into numba's caching internals, checked by
check_internals (and ``tests/test_fastpath.py``), which names the version when they changed."""


class NumbaChanged(RuntimeError):
    """numba's caching internals are not what this module was written against."""


@cache
def check_internals() -> None:
    """Raise :class:`NumbaChanged` (naming numba's version and the tested range) if the internals used here moved."""
    import numba
    from numba.core import caching, dispatcher

    missing = [
        what
        for what, ok in (
            ("numba.core.caching.FunctionCache", hasattr(caching, "FunctionCache")),
            ("FunctionCache.load_overload", hasattr(getattr(caching, "FunctionCache", None), "load_overload")),
            ("FunctionCache.save_overload", hasattr(getattr(caching, "FunctionCache", None), "save_overload")),
            ("IndexDataCacheFile._source_stamp", _has_source_stamp(caching)),
            ("Cache._cache_file", "_cache_file" in caching.Cache.__init__.__code__.co_names),
            ("Dispatcher._cache", "_cache" in dispatcher.Dispatcher.__init__.__code__.co_names),
        )
        if not ok
    ]
    if missing:
        (lo, hi) = TESTED
        raise NumbaChanged(
            f"numba {numba.__version__} lacks {', '.join(missing)}: riderlive.fastpath_cache is tested with "
            f"numba {lo[0]}.{lo[1]}-{hi[0]}.{hi[1]} (pyproject.toml); adapt it or install a tested numba"
        )


def _has_source_stamp(caching: Any) -> bool:
    """Whether numba's cache file keeps the source stamp this module extends (read from its code, not run)."""
    index_file = getattr(caching, "IndexDataCacheFile", None)
    init = getattr(index_file, "__init__", None)
    return init is not None and "_source_stamp" in init.__code__.co_names


def cache_for(py_func: Callable[..., Any]) -> Any:
    """numba's per-function disk cache whose freshness stamp also covers every source compiled in."""
    check_internals()
    from numba.core.caching import FunctionCache

    class SourcesCache(FunctionCache):  # type: ignore[misc]
        stamped = False

        def _stamp(self) -> None:
            if not self.stamped:  # on first use: by then every module the kernel calls is imported
                own = self._cache_file._source_stamp
                self._cache_file._source_stamp = (own, sources_stamp(py_func))
                self.stamped = True

        def load_overload(self, sig: Any, target_context: Any) -> Any:
            self._stamp()
            return super().load_overload(sig, target_context)  # type: ignore[no-untyped-call]

        def save_overload(self, sig: Any, data: Any) -> None:
            self._stamp()
            super().save_overload(sig, data)  # type: ignore[no-untyped-call]

    return SourcesCache(py_func)  # type: ignore[no-untyped-call]


def sources_stamp(fn: Callable[..., Any]) -> str:
    """A digest of the source files and module constants ``fn`` compiles in (kernels and helpers it calls,
    transitively). Closure values are left out: numba's cache keys entries on them already, and one index
    file holds the entries of every closure made by the same code (the rules of every preset)."""
    files: set[str] = set(COMPILE_FILES)
    constants: list[str] = []
    seen: set[int] = set()
    pending = [fn]
    while pending:
        f = cast(types.FunctionType, pending.pop())
        if id(f) in seen:
            continue
        seen.add(id(f))
        files.add(inspect.getfile(f))
        for name, value, is_global in _referenced(f):
            target = getattr(value, "py_func", value)
            if isinstance(target, types.FunctionType):
                pending.append(target)
            elif not is_global:
                continue
            elif isinstance(value, int | float | bool | str | tuple):
                constants.append(f"{name}={value!r}")
            elif isinstance(value, np.ndarray):
                constants.append(f"{name}={hashlib.sha256(value.tobytes()).hexdigest()}")
    digest = hashlib.sha256()
    for path in sorted(files):
        digest.update(path.encode() + _file_digest(path))
    digest.update("\n".join(sorted(constants)).encode())
    return digest.hexdigest()


def _referenced(fn: types.FunctionType) -> Iterator[tuple[str, Any, bool]]:
    """The globals and closure values ``fn``'s code reads (nested code objects included): name, value, global."""
    codes = [fn.__code__]
    names: set[str] = set()
    while codes:
        code = codes.pop()
        names.update(code.co_names)
        codes.extend(c for c in code.co_consts if isinstance(c, types.CodeType))
    for name in sorted(names):
        if name in fn.__globals__:
            yield name, fn.__globals__[name], True
    for name, cell in zip(fn.__code__.co_freevars, fn.__closure__ or (), strict=True):
        yield name, cell.cell_contents, False


@cache
def _file_digest(path: str) -> bytes:
    try:
        return hashlib.sha256(Path(path).read_bytes()).digest()
    except OSError:
        return b""
