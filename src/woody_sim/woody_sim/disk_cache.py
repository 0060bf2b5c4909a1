"""Loaded meshes and built chain models kept on disk between runs, so line_sim starts without redoing them.

Reading and repairing a scanned mesh costs ~0.3 s of CPU, building its chain model (height map, slices,
inertias, visuals) ~0.2 s, and line_sim does both for every mesh of its set before the line starts. Each result
is a function of its inputs and of the code that computes it, so it is stored under a digest of both
(``$WOODY_CACHE_DIR``, default ``~/.cache/woody``): a changed file, mesh or module gets another key, never a
stale entry. The cache is an optimisation only: an unreadable entry is recomputed, an unwritable folder skipped,
and a result that came with warnings (a mesh converted from millimetres) is not stored, so every run says them.
"""

from __future__ import annotations

import functools
import hashlib
import os
import pickle
import tempfile
import warnings
from collections.abc import Callable, Iterable
from pathlib import Path
from types import ModuleType
from typing import TypeVar

import numpy
import scipy
import trimesh

ENV_VAR = "WOODY_CACHE_DIR"
"""Overrides where the cache lives."""
_LIBRARIES = f"numpy {numpy.__version__} scipy {scipy.__version__} trimesh {trimesh.__version__}"
"""The numerical libraries the cached results come from: another version is another key."""

T = TypeVar("T")


def cache_dir(kind: str) -> Path:
    return Path(os.environ.get(ENV_VAR) or Path.home() / ".cache" / "woody") / kind


def digest(code: Iterable[ModuleType], *parts: object) -> str:
    """A key for a result of ``parts`` computed by the modules ``code``: their source, the libraries' versions
    and each part (bytes as they are, anything else by its repr)."""
    hasher = hashlib.sha256(_source_digest(tuple(code)))
    for part in parts:
        hasher.update(part if isinstance(part, bytes) else repr(part).encode())
        hasher.update(b"\0")
    return hasher.hexdigest()


@functools.cache
def _source_digest(code: tuple[ModuleType, ...]) -> bytes:
    """The libraries' versions and the modules' source, read once per process (a sweep keys every run)."""
    hasher = hashlib.sha256(_LIBRARIES.encode())
    for module in code:
        hasher.update(Path(module.__file__).read_bytes())
    return hasher.digest()


def cached(kind: str, key: str, compute: Callable[[], T], result_type: type) -> T:
    """``compute()``, read from ``kind/key`` when it was stored before, else computed and stored."""
    path = cache_dir(kind) / f"{key}.pickle"
    try:
        with open(path, "rb") as stored:
            result = pickle.load(stored)
        if isinstance(result, result_type):
            return result
    except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ImportError, TypeError, ValueError):
        pass
    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = compute()
    finally:  # said again outside the recording, whether compute() returned or raised
        for warning in caught:
            warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
    if not caught:
        _store(path, result)
    return result


def _store(path: Path, result: object) -> None:
    """Write atomically (a temporary file renamed), so a reader in another process never sees half an entry."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".tmp", delete=False) as out:
            pickle.dump(result, out, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(out.name, path)
    except OSError:
        pass
