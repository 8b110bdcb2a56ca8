"""Foreign packages under abacus' import names.

abacus ships three import packages: ``abacus``, ``acoustics`` and ``processing``. The last two
names are also those of other projects on PyPI — ``acoustics`` (python-acoustics) and
``processing`` (a backport of multiprocessing) —: installed in the same environment, one
overwrites the other's files, and abacus would die on an AttributeError deep inside. The command
line calls :func:`foreign_packages` first and says, in one line, which package is foreign and
what to do. Standard library only, and cheap: our two packages load their parts on first use.
"""
from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path

__all__ = ["foreign_packages", "OURS"]

#: our package -> (a name its public surface has, the PyPI project that takes its import name)
OURS = {
    "acoustics": ("simulate", "python-acoustics"),
    "processing": ("image", "the multiprocessing backport 'processing'"),
}


def _home() -> Path:
    return Path(__file__).resolve().parent.parent


def _foreign(name: str, marker: str) -> tuple[str, str] | None:
    """(where, why) when the package Python imports as ``name`` is not ours, else None."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError) as exc:
        return name, f"it cannot be found ({exc})"
    if spec is None:
        return name, "it is not installed (a damaged install: reinstall abacus)"
    where = spec.origin if spec.origin not in (None, "namespace") else \
        next(iter(spec.submodule_search_locations or []), name)
    path = Path(where).resolve()
    if not (spec.origin and path.name == "__init__.py" and path.parent.parent == _home()):
        return str(where), "it is not the one installed beside abacus"
    try:
        module = importlib.import_module(name)
    except Exception as exc:  # a foreign package may fail in any way on import
        return str(where), f"it fails to import ({exc.__class__.__name__}: {exc})"
    if marker not in getattr(module, "__all__", ()):
        return str(where), f"it has no {name}.{marker}"
    return None


def foreign_packages() -> str | None:
    """One line naming a foreign ``acoustics`` or ``processing`` and the remedy, or None when
    both are abacus' own."""
    for name, (marker, project) in OURS.items():
        found = _foreign(name, marker)
        if found is None:
            continue
        where, why = found
        return (f"the package '{name}' that Python imports ({where}) is not abacus' own ({why}): "
                f"'{name}' is also the import name of {project} on PyPI, and one install "
                f"overwrites the other; give abacus a virtual environment of its own "
                f"(python -m venv), or remove the other one (python -m pip uninstall {name}) "
                f"and reinstall abacus")
    return None
