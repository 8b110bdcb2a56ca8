"""``abacus count``: detect, locate and count the targets of a dataset."""
from __future__ import annotations

import json
from pathlib import Path

HELP = "detect, locate and count targets in a dataset"


def add_parser(sub):
    c = sub.add_parser("count", help=HELP)
    c.add_argument("input", help="dataset (.nc or .zarr); imaged first if needed")
    c.add_argument("-o", "--output", help="output dataset with detections and counts")
    c.add_argument("--settings", metavar="YAML", help="processing settings (default: the scene's)")
    c.add_argument("--json", action="store_true", help="print one JSON object: per-ping counts and summary")
    c.add_argument("--plots", metavar="DIR", help="detections over fan-beam images, counts vs ping")
    c.add_argument("--csv", metavar="FILE", help="write the detections table as CSV")
    c.set_defaults(func=command)


def command(args) -> int:
    import processing
    from processing.dataset import open_tree, write_tree
    tree = processing.count(open_tree(args.input), args.settings)
    result = processing.count_summary(tree)
    if args.output:
        write_tree(tree, Path(args.output))
    if args.csv:
        processing.write_csv(tree, args.csv)
    if args.plots:
        from processing.plots import count_figures
        n = tree["Processing/Counts"].sizes["ping_time"]
        count_figures(tree, Path(args.plots), pings=range(min(n, 5)))
    if args.json:
        print(json.dumps(result))
    else:
        print(processing.format_counts(result))
        for what, where in (("dataset", args.output), ("detections CSV", args.csv), ("plots", args.plots)):
            if where:
                print(f"wrote {what}: {where}")
    return 0
