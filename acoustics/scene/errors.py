"""The errors and warnings of scene files."""
from __future__ import annotations

from processing.base.config import ConfigError, ConfigWarning

__all__ = ["SceneError", "SceneWarning", "key_tuple", "located", "raise_problems", "warn_problems"]


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


def located(file, marks, key: str) -> str:
    """``file:line`` of a key path (its line from the file's marks), else ``file``."""
    line = (marks or {}).get(tuple(key_tuple(key)))
    return f"{file}:{line}" if line else str(file)


def raise_problems(problems, *, file, marks=None) -> None:
    """Raise one :class:`SceneError` for (message, key path) problems, each on its own line as
    ``file:line: key: message``; nothing when there are none."""
    if not problems:
        return
    lines = [f"{located(file, marks, key)}: {key}: {message}" for message, key in problems]
    head = f"{len(lines)} problems:\n" if len(lines) > 1 else ""
    raise SceneError(head + "\n".join(lines))


def warn_problems(problems, *, file, marks=None, stacklevel: int = 3) -> None:
    """A :class:`SceneWarning` for each (message, key path) pair, located like an error."""
    import warnings
    for message, key in problems:
        warnings.warn(f"{located(file, marks, key)}: {key}: {message}", SceneWarning,
                      stacklevel=stacklevel)
