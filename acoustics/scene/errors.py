"""The errors and warnings of scene files."""
from __future__ import annotations

from processing.base.config import ConfigError, ConfigWarning

__all__ = ["SceneError", "SceneWarning", "key_tuple"]


class SceneError(ConfigError):
    """A scene file that cannot be used; the message names file, line, key and remedy."""


class SceneWarning(ConfigWarning):
    """Legal but surprising physics in a scene (grating lobes, blind zone, ...)."""


def key_tuple(key: str):
    """``"targets.points[2].range_m"`` → ``["targets", "points", 2, "range_m"]`` (to find a key's
    line in a file's marks)."""
    out = []
    for part in key.replace("]", "").split("."):
        if "[" in part:
            head, *idx = part.split("[")
            out.append(head)
            out.extend(int(i) for i in idx)
        else:
            out.append(part)
    return out
