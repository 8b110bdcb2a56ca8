"""Results that depend only on the sonar's geometry, computed once per process.

Keyed by the bytes of the element geometry (and whatever else the result depends on), so arrays
rebuilt from the same scene hit the cache; identity-keyed caches (``lru_cache`` on arrays)
never do.
"""
from __future__ import annotations

import numpy as np

__all__ = ["array_key", "per_geometry"]

_CACHE: dict = {}
_MAX_ENTRIES = 64


def array_key(arr) -> bytes:
    """Bytes identifying an :class:`~acoustics.sonar.arrays.ElementArray`'s geometry."""
    return b"".join(np.ascontiguousarray(a).tobytes() for a in
                    (arr.center_m, arr.width_m, arr.height_m, arr.rotation_rad, arr.weight))


def per_geometry(name: str, key, compute):
    """``compute()`` once per process for (name, key); later calls return the stored result."""
    k = (name, key)
    if k not in _CACHE:
        if len(_CACHE) >= _MAX_ENTRIES:
            _CACHE.clear()
        _CACHE[k] = compute()
    return _CACHE[k]
