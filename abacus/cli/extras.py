"""The optional extras a command's arguments call for, checked before the command starts, so
that a missing one ends it in one line naming the extra (exit status 2) rather than after the
work, or as an unreadable-file error (xarray without zarr knows no ``zarr`` engine).

What the command finds out only later — an experiment's Dask workers (``plan_workers``),
tracking scores (motmetrics, when the dataset holds the truth) — raises
:class:`processing.base.extras.MissingExtra` there; :mod:`abacus.cli.app` prints it the same way.
"""
from __future__ import annotations

from pathlib import Path

from processing.base.extras import require

__all__ = ["check_extras"]

#: commands that read or write datasets (.nc, or Zarr with the extra ``zarr``)
DATASET_COMMANDS = ("simulate", "image", "count", "targets", "track", "sv", "convert", "experiment")

#: files that make a folder a Zarr store (v2 and v3)
_ZARR_MARKS = (".zgroup", ".zattrs", ".zmetadata", "zarr.json")


def _is_zarr_input(path: str) -> bool:
    p = Path(path)
    if p.suffix.lower() == ".zarr":
        return True
    return p.is_dir() and any((p / m).exists() for m in _ZARR_MARKS)


def check_extras(args) -> None:
    """Raise :class:`~processing.base.extras.MissingExtra` when the parsed command line needs an
    extra that is not installed."""
    command = getattr(args, "command", None)
    if command == "view":
        require("pyvista", "abacus view")
    if command not in DATASET_COMMANDS:
        return
    inp, out, fmt = (getattr(args, k, None) for k in ("input", "output", "format"))
    zarr = None
    if inp and _is_zarr_input(inp):
        zarr = inp
    elif fmt == "zarr":
        zarr = out or "--format zarr"
    elif out and fmt is None and command != "experiment" and Path(out).suffix.lower() == ".zarr":
        zarr = out
    if zarr is not None:
        require("zarr", f"abacus {command} with Zarr ({zarr})")
