"""Results that depend only on the sonar's geometry, computed once — per process, and on disk.

Keyed by the bytes of what they depend on (element geometry, frequency, sound speed), so arrays
rebuilt from the same scene hit the cache; identity-keyed caches (``lru_cache`` on arrays) never
do. The disk layer keeps results between runs and processes (experiment workers, the next
``abacus run``): one small file per result under :func:`cache_dir` — ``$ABACUS_CACHE_DIR``, else
the user cache folder (``~/.cache/abacus``) — written atomically, named by a hash of the key,
abacus' version and :data:`CACHE_VERSION`. The folder is safe to delete at any time; an unreadable
entry is recomputed, never an error. ``ABACUS_CACHE_DIR=off`` turns the disk layer off.
"""
from __future__ import annotations

import hashlib
import io
import json
import os
from pathlib import Path

import numpy as np

__all__ = ["array_key", "per_geometry", "cached", "cache_dir", "clear_memory", "CACHE_VERSION"]

#: bump when a cached computation changes its result
CACHE_VERSION = 1
_CACHE: dict = {}
_MAX_ENTRIES = 64


def array_key(arr) -> bytes:
    """Bytes identifying an :class:`~acoustics.sonar.arrays.ElementArray`'s geometry."""
    return b"".join(np.ascontiguousarray(a).tobytes() for a in
                    (arr.center_m, arr.width_m, arr.height_m, arr.rotation_rad, arr.weight))


def clear_memory() -> None:
    """Forget the results held in memory (the disk layer stays): the next request reads the disk
    or computes, as a new process would."""
    _CACHE.clear()


def cache_dir() -> Path | None:
    """The disk cache folder, or None when the disk layer is off."""
    env = os.environ.get("ABACUS_CACHE_DIR")
    if env is not None:
        return None if env.strip().lower() in ("", "off", "0", "none") else Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or (Path.home() / ".cache")
    return Path(base) / "abacus"


def _file(name: str, key) -> Path | None:
    folder = cache_dir()
    if folder is None:
        return None
    from acoustics import __version__
    digest = hashlib.sha256(repr((name, key, __version__, CACHE_VERSION)).encode()).hexdigest()[:24]
    return folder / f"{name}-{digest}"


def _load(path: Path):
    """A stored value: a JSON object, or a tuple of arrays/floats (npz, no pickles)."""
    try:
        if path.with_suffix(".json").is_file():
            return json.loads(path.with_suffix(".json").read_text())
        with np.load(path.with_suffix(".npz"), allow_pickle=False) as z:
            items = [z[f"item{i}"] for i in range(len(z.files))]
        return tuple(float(a) if a.ndim == 0 else a for a in items)
    except Exception:  # missing, truncated, written by another version: recompute
        return None


def _store(path: Path, value) -> None:
    from processing.base.atomic import write_bytes_atomic
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(value, dict):
            write_bytes_atomic(path.with_suffix(".json"), json.dumps(value).encode())
        else:
            buf = io.BytesIO()
            np.savez(buf, **{f"item{i}": np.asarray(v) for i, v in enumerate(value)})
            write_bytes_atomic(path.with_suffix(".npz"), buf.getvalue())
    except OSError:  # a read-only or full disk only costs the next run the computation
        pass


def cached(name: str, key, *, disk: bool = True):
    """The value :func:`per_geometry` holds for (name, key), from memory or disk, or None when
    it would have to be computed (nothing is computed here)."""
    k = (name, key)
    if k in _CACHE:
        return _CACHE[k]
    path = _file(name, key) if disk else None
    value = _load(path) if path is not None else None
    if value is not None:
        _remember(k, value)
    return value


def _remember(k, value):
    if len(_CACHE) >= _MAX_ENTRIES:
        _CACHE.clear()
    _CACHE[k] = value


def per_geometry(name: str, key, compute, *, disk: bool = True):
    """``compute()`` once for (name, key): from memory, else from the disk cache, else computed
    (and stored in both). ``key`` must be hashable and have a stable ``repr`` (bytes, numbers,
    strings and tuples of them); the value a JSON-able dict or a tuple of arrays and floats."""
    value = cached(name, key, disk=disk)
    if value is None:
        value = compute()
        path = _file(name, key) if disk else None
        if path is not None:
            _store(path, value)
        _remember((name, key), value)
    return value
