"""Public names imported on first use: what keeps ``import acoustics, processing, abacus`` cheap.

A package lists its public names with the module that defines each; :func:`public_api` gives it
the module-level ``__getattr__`` (PEP 562) and ``__dir__`` that import that module the first time
a name is asked for, and ``__all__``. Standard library only: every layer may use it.
"""
from __future__ import annotations

import importlib

__all__ = ["public_api", "distribution_version"]


def public_api(package: str, api: dict, namespace: dict, extra=()):
    """``(__getattr__, __dir__, __all__)`` of a package whose names load lazily.

    Parameters
    ----------
    package : str
        The package's name (for the AttributeError of an unknown name).
    api : dict
        Public name -> dotted module that defines it.
    namespace : dict
        The package's ``globals()``: a name, once loaded, is stored there (no second lookup).
    extra : iterable of str
        Names the package defines itself (``__version__``), listed in ``__all__`` too.
    """
    names = sorted(api) + list(extra)

    def __getattr__(name):
        module = api.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def __dir__():
        return names

    return __getattr__, __dir__, names


def distribution_version(name: str = "abacus") -> str:
    """The installed distribution's version, or ``"0+unknown"`` when running from a source tree."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version(name)
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "0+unknown"
