"""The errors and warnings of scene files."""
from __future__ import annotations

from processing.config import ConfigError, ConfigWarning

__all__ = ["SceneError", "SceneWarning"]


class SceneError(ConfigError):
    """A scene file that cannot be used; the message names file, line, key and remedy."""


class SceneWarning(ConfigWarning):
    """Legal but surprising physics in a scene (grating lobes, blind zone, ...)."""
