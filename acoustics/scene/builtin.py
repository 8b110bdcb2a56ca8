"""The scenes shipped with abacus, found by name wherever abacus is installed.

In a source checkout they are the files of ``scenes/``; an installed abacus carries the same
files as the package ``abacus_scenes`` (package data). A command's SCENE argument is a path
when such a file exists, else the name of a built-in scene (``default`` or ``default.yaml``).
"""
from __future__ import annotations

from pathlib import Path

from acoustics.scene.errors import SceneError

__all__ = ["scenes_dir", "builtin_scenes", "builtin_scene", "resolve_scene_argument", "did_you_mean"]


def scenes_dir() -> Path:
    """The folder holding the built-in scene files."""
    import abacus_scenes
    return Path(abacus_scenes.__file__).resolve().parent


def builtin_scenes() -> list[str]:
    """Names of the built-in scenes, sorted."""
    return sorted(p.stem for p in scenes_dir().glob("*.yaml"))


def builtin_scene(name: str) -> Path:
    """The file of the built-in scene ``name`` (with or without ``.yaml``).

    Raises
    ------
    SceneError
        No built-in scene of that name; the message lists them.
    """
    stem = name[:-5] if name.endswith(".yaml") else name
    names = builtin_scenes()
    if stem not in names:
        raise SceneError(f"{name}: no such scene file, and no built-in scene of that name"
                         f"{did_you_mean(stem, names)}; built-in scenes: {', '.join(names)}")
    return scenes_dir() / f"{stem}.yaml"


def did_you_mean(name: str, names, *, cutoff: float = 0.75) -> str:
    """" (did you mean 'X'?)" for the name of ``names`` closest to a mistyped ``name``
    (difflib's ratio at least ``cutoff``, case ignored), or "" when none is close."""
    import difflib
    by_lower = {n.lower(): n for n in names}
    close = difflib.get_close_matches(str(name).lower(), list(by_lower), n=1, cutoff=cutoff)
    return f" (did you mean '{by_lower[close[0]]}'?)" if close else ""


def resolve_scene_argument(arg) -> Path:
    """A path when the file exists (or the argument looks like a path), else a built-in scene."""
    p = Path(arg)
    if p.exists() or len(p.parts) > 1:
        return p
    return builtin_scene(str(arg))
