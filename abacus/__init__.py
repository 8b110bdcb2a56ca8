"""abacus — the application: the ``abacus`` command, run folders, experiments, results, report,
figures and the 3-D view, over the two libraries below it.

Layers (docs/architecture.md)::

    abacus       the application (this package): imports acoustics and processing
    acoustics    the forward model: scene -> per-element echoes; imports only processing.base
    processing   the inverse model: echoes -> images -> detections -> tracks, counts, Sv;
                 imports neither

Public surface (imported on first use, so ``import abacus`` is cheap)::

    run_experiment(scene, folder, ...) -> Path   # Monte Carlo over pings and sweeps (Dask)
    main(argv) -> int                            # the command line
"""
from __future__ import annotations

import importlib

try:
    from importlib.metadata import PackageNotFoundError, version as _dist_version
    __version__ = _dist_version("abacus")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"

#: public name -> module that defines it
_API = {
    "run_experiment": "abacus.experiment",
    "main": "abacus.cli.app",
}

__all__ = sorted(_API) + ["__version__"]


def __getattr__(name):
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'abacus' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
