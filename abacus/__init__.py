"""abacus — the application: the ``abacus`` command, run folders, experiments, results, report,
figures and the 3-D view, over the two libraries below it.

Layers (docs/architecture.md)::

    abacus       the application (this package): imports acoustics and processing
    acoustics    the forward model: scene -> per-element echoes; imports only processing.base
    processing   the inverse model: echoes -> images -> detections -> tracks, counts, Sv;
                 imports neither

Public surface (imported on first use, so ``import abacus`` is cheap)::

    run(scene, output=None, *, pings, plots, images, ...) -> RunResult   # what `abacus run` does
    run_experiment(scene, folder, ...) -> Path   # Monte Carlo over pings and sweeps (Dask)
    main(argv) -> int                            # the command line
"""
from __future__ import annotations

from processing.base.lazy import distribution_version, public_api

__version__ = distribution_version("abacus")

#: public name -> module that defines it
_API = {
    "run": "abacus.runs", "RunResult": "abacus.runs",
    "run_experiment": "abacus.experiment",
    "main": "abacus.cli.app",
}

__getattr__, __dir__, __all__ = public_api("abacus", _API, globals(), extra=["__version__"])
