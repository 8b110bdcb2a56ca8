"""The scenes shipped with abacus, found by name wherever abacus is installed.

In a source checkout they are the files of ``scenes/``; an installed abacus carries the same
files as the package ``abacus_scenes`` (package data). A command's SCENE argument is a path
when such a file exists, else the name of a built-in scene (``default`` or ``default.yaml``).
"""
from __future__ import annotations

from pathlib import Path

from acoustics.scene.errors import SceneError

__all__ = ["scenes_dir", "builtin_scenes", "builtin_scene", "resolve_scene_argument"]


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
    if stem not in builtin_scenes():
        raise SceneError(f"{name}: no such scene file, and no built-in scene of that name; "
                         f"built-in scenes: {', '.join(builtin_scenes())}")
    return scenes_dir() / f"{stem}.yaml"


def resolve_scene_argument(arg) -> Path:
    """A path when the file exists (or the argument looks like a path), else a built-in scene."""
    p = Path(arg)
    if p.exists() or len(p.parts) > 1:
        return p
    return builtin_scene(str(arg))
