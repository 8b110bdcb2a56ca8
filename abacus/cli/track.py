"""``abacus track``: track the fish of a dataset across pings, count each passage once."""
from __future__ import annotations

import json

from abacus.cli.common import add_output_options, check_output

HELP = "track detections across pings: per-fish tracks, TS, speed and track-based counts"


def add_parser(sub):
    c = sub.add_parser("track", help=HELP)
    c.add_argument("input", help="dataset (.nc or .zarr); detected and counted first if needed")
    c.add_argument("-o", "--output", help="output dataset with /Processing/Tracks")
    c.add_argument("--settings", metavar="YAML", help="processing settings (default: the scene's)")
    c.add_argument("--json", action="store_true", help="print one JSON object: per-track rows and summary")
    c.add_argument("--csv", metavar="FILE", help="write one row per track as CSV")
    c.add_argument("--plots", metavar="DIR", help="tracks in 3-D and from above and the side; TS along tracks")
    add_output_options(c)
    c.set_defaults(func=command)


def command(args) -> int:
    import processing
    from processing.base.dataset import open_tree, write_tree
    from processing.tracking.tracks import format_tracks, track_summary, write_tracks_csv
    out = check_output(args.output, overwrite=args.overwrite) if args.output else None
    csv = check_output(args.csv, overwrite=args.overwrite, option="--csv") if args.csv else None
    plots = check_output(args.plots, overwrite=args.overwrite, option="--plots", folder=True) if args.plots else None
    tree = open_tree(args.input, max_memory_gb=args.max_memory, work_factor=3.0)
    if "Processing" not in tree.children or "Counts" not in tree["Processing"].children:
        tree = processing.count(tree, args.settings)
    tree = processing.track(tree, args.settings)
    result = track_summary(tree)
    if out is not None:
        write_tree(tree, out)
    if csv is not None:
        write_tracks_csv(tree, csv)
    if plots is not None:
        from processing.base.atomic import staged
        from abacus.figures.tracks import track_figures
        with staged(plots) as tmp:
            track_figures(tree, tmp)
    if args.json:
        print(json.dumps(result))
    else:
        print(format_tracks(result))
        for what, where in (("dataset", args.output), ("tracks CSV", args.csv), ("plots", args.plots)):
            if where:
                print(f"wrote {what}: {where}")
    return 0
