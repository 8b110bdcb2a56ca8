"""``abacus scene check|show|schema``: validate a scene, print it resolved, print the schema."""
from __future__ import annotations

import sys

from abacus.cli.common import UsageError, add_output_options, check_scene_resources, load

HELP = "check a scene file, show it resolved, or print the schema"


def add_parser(sub):
    s = sub.add_parser("scene", help=HELP)
    s.add_argument("action", choices=["check", "show", "schema"])
    s.add_argument("file", nargs="?", help="scene file (YAML) or a built-in scene's name")
    add_output_options(s, overwrite=False)
    s.set_defaults(func=command)


def command(args) -> int:
    from abacus.runfile import json_schema_text
    if args.action == "schema":
        sys.stdout.write(json_schema_text())
        return 0
    if args.file is None:
        raise UsageError(f"abacus scene {args.action}: give a scene FILE")
    scene = load(args.file)   # meshes and grids checked by the file gate, a motion file read whole
    if args.action == "check":
        # the estimate first, from the keys and the files' headers: a plane of 10^5 x 10^5
        # segments or a mesh file of 10^9 faces is refused here, before it is built
        est = check_scene_resources(scene, args, figures=True)
        noise = check_noise_file(scene, max_memory_gb=getattr(args, "max_memory", None),
                                 shown=args.file)
        meshes = ""
        if scene.boundaries or scene.targets.meshes:
            # build every mesh now, so a bad mesh file fails here and not mid-run
            from acoustics.paths.meshes import scene_meshes
            from acoustics.simulation.setup import resolve_mesh_sources
            from acoustics.sonar.build import build_sonar
            built = scene_meshes(resolve_mesh_sources(scene), build_sonar(scene).pose)
            meshes = f", {len(built)} mesh(es), {sum(m.n_faces for m in built)} faces"
        motion = ""
        if scene.sonar.motion is not None and scene.sonar.motion.kind == "file":
            from acoustics.sonar.platform import read_motion_csv
            rows = len(read_motion_csv(scene.sonar.motion.file, folder=scene.resolve_path("."))["time_s"])
            motion = f", motion file of {rows} row(s)"
        print(f"{args.file}: ok — scene '{scene.name}', {scene.pings.count} ping(s){meshes}{motion}"
              f"{noise}, sha256 {scene.sha256()[:12]}")
        print(f"  `abacus run` will need {est.describe()}")
        from acoustics.scene.checks import cross_check
        notes: list = []
        cross_check(scene, notes=notes)
        for message, key in notes:
            print(f"  note: {key}: {message}")
    else:
        sys.stdout.write(scene.resolved_text())
    return 0


def check_noise_file(scene, *, max_memory_gb=None, shown=None) -> str:
    """Open and check the noise-only dataset a scene's processing names
    (``processing.detect.noise.file`` with ``source: noise_file``), as the detection of
    ``abacus run`` would: through the file gate (in the scene's folder or below, relative to
    it; :mod:`processing.base.files`), then read as a record of the data contract.

    Parameters
    ----------
    scene : Scene
    max_memory_gb : float, optional
        The memory limit for reading it (``--max-memory``).
    shown : str, optional
        The scene file as the user named it, for messages (default its full path).

    Returns
    -------
    str
        ", noise file NAME (P pings)" for the summary line, or "" when the scene names none.

    Raises
    ------
    SceneError
        The file refused or unreadable, with the scene file, line and key.
    """
    from abacus.runfile import settings_of
    from acoustics.scene import SceneError
    noise = settings_of(scene).detect.noise
    if noise.source != "noise_file" or not noise.file:
        return ""
    from processing.base.config import ConfigError, read_yaml
    from processing.base.dataset import DatasetError, open_tree, read_record
    from processing.base.files import FileRefused, check_file
    key = "processing.detect.noise.file"
    where = str(shown or scene.source_path or scene.name)
    try:
        _, marks = read_yaml(scene.source_path) if scene.source_path else (None, {})
        line = marks.get(("processing", "detect", "noise", "file"))
        where = f"{where}:{line}" if line else where
    except ConfigError:
        pass
    folder = scene.resolve_path(".")
    try:
        f = check_file(noise.file, folder=folder, max_bytes=None, what="noise file", key=key,
                       where=where, allow_folder=True,
                       accepts="a noise-only dataset (NetCDF4 or Zarr) in the scene's folder")
        tree = open_tree(f.path, max_memory_gb=max_memory_gb)
        rec = read_record(tree, source=str(f.path))
    except FileRefused as exc:
        raise SceneError(str(exc)) from None
    except DatasetError as exc:
        raise SceneError(f"{where}: {key}: {exc}") from None
    return f", noise file {noise.file} ({rec.samples.shape[0]} ping(s))"
