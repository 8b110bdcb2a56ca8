"""What every command shares: the usage error, scene loading, ping lists, a progress bar."""
from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["UsageError", "load", "ping_list", "Progress", "default_scene_path"]


class UsageError(Exception):
    """A bad option or argument: printed as one line, exit status 2."""


def default_scene_path() -> Path:
    """The built-in default scene (shipped with the package)."""
    from acoustics.scene.builtin import builtin_scene
    return builtin_scene("default")


def load(path):
    """Load a scene file, or a built-in scene by name (``default``, ``two_targets``, ...)."""
    from acoustics.scene.builtin import resolve_scene_argument
    from acoustics.scene.load import load_scene
    return load_scene(resolve_scene_argument(path))


class Progress:
    """A one-line progress bar on stderr, only when stderr is a terminal."""

    def __init__(self, label: str):
        self.label = label
        self.on = sys.stderr.isatty()

    def __call__(self, done: int, total: int):
        if not self.on:
            return
        width = 30
        fill = int(width * done / max(total, 1))
        end = "\n" if done >= total else ""
        print(f"\r{self.label} [{'#' * fill}{'.' * (width - fill)}] {done}/{total}", end=end,
              file=sys.stderr, flush=True)


def ping_list(scene, n: int | None):
    """Pings first .. first + n − 1 of the scene, or None (the scene's own) when n is None."""
    if n is None:
        return None
    if n < 1:
        raise UsageError(f"--pings must be >= 1, got {n}")
    return range(scene.pings.first, scene.pings.first + n)
