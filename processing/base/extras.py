"""Optional dependencies: which extra of the ``abacus`` distribution brings each, and the error
that names it.

A minimal install (``pip install abacus``) simulates, processes and runs ``abacus run`` with its
figures; the rest comes in extras (pyproject.toml)::

    view        pyvista               abacus view (the 3-D picture)
    experiment  dask[distributed]     abacus experiment on Dask workers (alias: dask)
    zarr        zarr                  datasets and results as Zarr
    metrics     motmetrics            tracking scores against the truth (MOTA, IDF1)

Code that needs one imports it through :func:`require`, which raises :class:`MissingExtra` (an
``ImportError``) whose message names the extra and the command that installs it; the command
line prints that message as its one line, exit status 2. Standard library only: every layer may
import it.
"""
from __future__ import annotations

import importlib

__all__ = ["MissingExtra", "EXTRAS", "require", "missing_extra"]

#: top-level module -> the extra that installs it
EXTRAS = {
    "pyvista": "view", "vtk": "view",
    "dask": "experiment", "distributed": "experiment",
    "zarr": "zarr", "numcodecs": "zarr",
    "motmetrics": "metrics",
}


class MissingExtra(ImportError):
    """An optional dependency that is not installed; the message names the extra to install,
    e.g. ``abacus view needs the extra 'view': pip install "abacus[view]"``.

    Attributes
    ----------
    extra : str
        The extra of the ``abacus`` distribution that brings the module.
    """

    def __init__(self, what: str, extra: str, module: str | None = None):
        super().__init__(f"{what} needs the extra '{extra}': pip install \"abacus[{extra}]\"",
                         name=module)
        self.extra = extra
        self.what = what


def _top(name: str | None) -> str:
    return (name or "").split(".")[0]


def missing_extra(exc: BaseException, what: str | None = None) -> MissingExtra | None:
    """The :class:`MissingExtra` an import error amounts to, or None when it is not one.

    ``exc`` counts when it is a :class:`MissingExtra`, or a ``ModuleNotFoundError`` for a module
    of :data:`EXTRAS` (e.g. xarray failing to import zarr). Any other import error (a module
    that is there but broken, a missing system library) is not a missing extra: None.
    """
    if isinstance(exc, MissingExtra):
        return exc
    if isinstance(exc, ModuleNotFoundError) and _top(exc.name) in EXTRAS:
        module = _top(exc.name)
        return MissingExtra(what or f"the module {module!r}", EXTRAS[module], module)
    return None


def require(module: str, what: str):
    """Import ``module`` (one of :data:`EXTRAS`' modules, or a submodule of one) and return it.

    Parameters
    ----------
    module : str
        e.g. ``"motmetrics"``, ``"dask.distributed"``.
    what : str
        What needs it, as the message's subject: ``"abacus view"``, ``"tracking scores"``.

    Raises
    ------
    MissingExtra
        The module (or a module of an extra it imports) is not installed.
    """
    extra = EXTRAS[_top(module)]
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if _top(exc.name) == _top(module):
            raise MissingExtra(what, extra, _top(module)) from None
        found = missing_extra(exc, what)      # e.g. dask there, distributed not
        if found is None:                     # a broken install, not a missing extra
            raise
        raise found from None
