"""Reading a scene file: YAML with line numbers, validation, file checks, physics warnings."""
from __future__ import annotations

from pathlib import Path

from acoustics.scene.builtin import resolve_scene_argument
from acoustics.scene.checks import cross_check
from acoustics.scene.errors import SceneError, key_tuple, located, warn_problems
from acoustics.scene.schema import Scene
from acoustics.sonar.platform import MotionFileError, read_motion_csv
from processing.base.config import ConfigError, parse_yaml, read_yaml
from processing.base.files import FileRefused, check_file

__all__ = ["load_scene", "scene_from_text", "scene_from_resolved_text", "validate_scene", "mesh_files",
           "key_tuple", "MotionSceneError"]


class MotionSceneError(SceneError, MotionFileError):
    """A motion file a scene names that cannot be used, found at the scene's load: a
    :class:`SceneError` and a :class:`~acoustics.sonar.platform.MotionFileError`."""


def validate_scene(data, *, file, marks=None, source_path=None) -> Scene:
    """Validate scene data (a dict as YAML gives it); see :meth:`Scene.validated`."""
    return Scene.validated(data, file=file, marks=marks, source_path=source_path)


def scene_from_resolved_text(text: str, *, source_path=None) -> Scene:
    """A scene from the resolved YAML a run recorded (:meth:`Scene.resolved_text`).

    Parameters
    ----------
    text : str
    source_path : str or Path, optional
        The scene file it came from (mesh paths resolve relative to its folder).

    Raises
    ------
    SceneError
    """
    try:
        data, _ = parse_yaml(text, source=str(source_path or "<scene text>"))
    except ConfigError as exc:
        raise SceneError(str(exc)) from None
    if not isinstance(data, dict):
        raise SceneError(f"{source_path or '<scene text>'}: not a scene (a YAML mapping of sections)")
    return Scene.validated(data, file=source_path or "<scene>", source_path=source_path)


def load_scene(path: str | Path, *, check: bool = True) -> Scene:
    """Read, validate and resolve a scene file.

    Parameters
    ----------
    path : str or Path
        A YAML scene file (mesh paths inside it resolve relative to its folder), or the name of
        a scene shipped with abacus (``"default"``, ``"two_targets"``, ...; see
        :func:`acoustics.scene.builtin.builtin_scenes`) when no such file exists.
    check : bool
        Run the physics cross-checks, which emit :class:`SceneWarning` (never fail).

    Returns
    -------
    Scene
        Frozen; SI units, angles in radians.

    Raises
    ------
    SceneError
        Unreadable file, YAML syntax error, unknown key, wrong type, bad value. The
        message names the file, line, key path, value and what is accepted.

    Examples
    --------
    >>> scene = acoustics.load_scene("scenes/two_targets.yaml")
    >>> scene.name, scene.pings.count
    ('two-targets', 1)
    >>> acoustics.load_scene("default").sonar.mode        # a built-in scene by name
    'interferometric'
    """
    path = resolve_scene_argument(path)
    try:
        data, marks = read_yaml(path)
    except ConfigError as exc:
        raise SceneError(str(exc)) from None
    if data is None:
        raise SceneError(f"{path}: the file is empty; a scene needs at least 'name'")
    scene = validate_scene(data, file=path, marks=marks, source_path=path.resolve())
    _check_files(scene, path, marks)
    if check:
        warn_problems(cross_check(scene), file=path, marks=marks)
    return scene


def mesh_files(scene: Scene):
    """(key, path written in the scene) of every file a scene's meshes read."""
    items = [(f"boundaries[{i}]", b) for i, b in enumerate(scene.boundaries)]
    items += [(f"targets.meshes[{i}]", t) for i, t in enumerate(scene.targets.meshes)]
    for key, spec in items:
        file = getattr(spec.mesh, "file", None)
        if file is not None:
            yield f"{key}.mesh.file", file


#: mesh and height-grid files a scene may read (bytes)
MAX_MESH_FILE_BYTES = 256 * 1024 ** 2


def _check_files(scene: Scene, path: Path, marks):
    """Every file a scene names goes through the file gate (:mod:`processing.base.files`) at
    load, not mid-run: mesh and height-grid files exist, are regular files of a bounded size and
    lie in the scene file's folder (or below it) — a scene may not read files elsewhere
    (``/etc/passwd``, another user's data) unless the person running it sets
    ``ABACUS_ALLOW_OUTSIDE_FILES=1``; a motion file is read and validated whole (its rows are
    kept for the run), so every problem of it is reported here."""
    home = path.resolve().parent

    def where(key):
        return located(path, marks, key)

    for key, file in mesh_files(scene):
        try:
            check_file(file, folder=home, max_bytes=MAX_MESH_FILE_BYTES, what="mesh file", key=key,
                       where=where(key), accepts="a mesh or height-grid file")
        except FileRefused as exc:
            raise SceneError(str(exc)) from None
    motion = scene.sonar.motion
    if motion is not None and motion.kind == "file":
        key = "sonar.motion.file"
        try:
            read_motion_csv(motion.file, folder=home, key=key, where=where(key))
        except MotionFileError as exc:
            raise MotionSceneError(str(exc)) from None


def scene_from_text(text: str, *, name: str = "<text>", check: bool = False) -> Scene:
    """Validate a scene given as YAML text (tests, notebooks)."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "scene.yaml"
        p.write_text(text)
        try:
            return load_scene(p, check=check)
        except SceneError as exc:
            raise SceneError(str(exc).replace(str(p), name), exc.problems) from None
