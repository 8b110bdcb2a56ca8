"""xarray without the imports abacus never needs: Dask is looked up only once it is loaded.

xarray asks "is this a Dask array / collection?" on every variable it wraps and "is a Dask
scheduler running?" on every write, and answers by importing ``dask.array`` (≈ 0.6 s),
``dask`` (≈ 0.25 s) and ``distributed`` (≈ 0.2 s) whenever they are installed. abacus installs Dask for
``abacus experiment`` but never makes Dask arrays. Both questions have an exact answer without
the import: no object can be a ``dask.array.Array`` before ``dask.array`` is imported, and no
Dask collection or scheduler can exist before ``dask`` is. :func:`install` makes xarray ask that way; once a
process imports Dask itself, xarray's own answers apply again, unchanged.

If xarray's internals move, :func:`install` leaves xarray as it is (slower to start, never
wrong); tests/test_pipeline.py checks that a run still avoids the imports.
"""
from __future__ import annotations

import sys

__all__ = ["install"]

_installed = False


class _DaskProbe:
    """xarray's record of the ``dask`` duck-array module, resolved at each use."""

    def _real(self):
        from xarray.namedarray import pycompat
        real = pycompat.DuckArrayModule("dask")
        pycompat._cached_duck_array_modules["dask"] = real   # from now on xarray's own
        return real

    @property
    def type(self):
        if "dask.array" not in sys.modules:
            return ()
        return self._real().type

    def __getattr__(self, name):          # module, version, available: the real lookup
        return getattr(self._real(), name)


def install() -> None:
    """Make xarray look Dask up only once it is loaded (idempotent)."""
    global _installed
    if _installed:
        return
    _installed = True
    try:
        from xarray.backends import locks, writers
        from xarray.core import utils as core_utils
        from xarray.namedarray import pycompat
        from xarray.namedarray import utils as named_utils
    except ImportError:        # pragma: no cover - another xarray layout: keep its behaviour
        return
    cache = getattr(pycompat, "_cached_duck_array_modules", None)
    if isinstance(cache, dict) and "dask" not in cache and "dask.array" not in sys.modules:
        cache["dask"] = _DaskProbe()
    collection = getattr(named_utils, "is_dask_collection", None)
    if callable(collection):
        def is_dask_collection(x):
            return "dask" in sys.modules and collection(x)
        for module in (named_utils, core_utils):
            if getattr(module, "is_dask_collection", None) is collection:
                module.is_dask_collection = is_dask_collection
    scheduler = getattr(locks, "get_dask_scheduler", None)
    if callable(scheduler):
        def get_dask_scheduler(*args, **kwargs):
            if "dask" not in sys.modules:
                return None        # what xarray itself returns where Dask is not installed
            return scheduler(*args, **kwargs)
        for module in (locks, writers):
            if getattr(module, "get_dask_scheduler", None) is scheduler:
                module.get_dask_scheduler = get_dask_scheduler
