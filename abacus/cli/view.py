"""``abacus view``: a 3-D picture of a scene (needs the optional ``view`` extra: pyvista)."""
from __future__ import annotations

from abacus.cli.common import UsageError, add_output_options, check_output, load

HELP = "3-D view of a scene (meshes, sonar, beam, targets)"


def add_parser(sub):
    v = sub.add_parser("view", help=HELP)
    v.add_argument("scene", help="scene file (YAML) or a built-in scene's name")
    v.add_argument("-o", "--output", help="PNG file to write")
    v.add_argument("--ping", type=int, default=0, help="ping whose targets and sea to draw")
    v.add_argument("--interactive", action="store_true", help="open a window (needs a display)")
    add_output_options(v, memory=False)
    v.set_defaults(func=command)


def command(args) -> int:
    from processing.base.extras import require
    require("pyvista", "abacus view")     # the extra `view`: one line naming it, exit status 2
    from abacus.view import render_scene
    if args.output:
        check_output(args.output, overwrite=args.overwrite)
    elif not args.interactive:
        raise UsageError("abacus view: give -o PNG (or --interactive with a display)")
    scene = load(args.scene)
    out = render_scene(scene, args.output, ping=args.ping, interactive=args.interactive)
    if out:
        print(f"wrote {out}")
    return 0
