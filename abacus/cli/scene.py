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
    scene = load(args.file)
    if args.action == "check":
        meshes = ""
        if scene.boundaries or scene.targets.meshes:
            # build every mesh now, so a bad mesh file fails here and not mid-run
            from acoustics.paths.meshes import scene_meshes
            from acoustics.sonar.build import build_sonar
            built = scene_meshes(scene, build_sonar(scene).pose)
            meshes = f", {len(built)} mesh(es), {sum(len(m.mesh.faces) for m in built)} faces"
        est = check_scene_resources(scene, args, figures=True)
        print(f"{args.file}: ok — scene '{scene.name}', {scene.pings.count} ping(s){meshes}, "
              f"sha256 {scene.sha256()[:12]}")
        print(f"  `abacus run` will need {est.describe()}")
        from acoustics.scene.checks import cross_check
        notes: list = []
        cross_check(scene, notes=notes)
        for message, key in notes:
            print(f"  note: {key}: {message}")
    else:
        sys.stdout.write(scene.resolved_text())
    return 0
