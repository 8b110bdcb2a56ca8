"""``abacus count``: detect, locate and count the targets of a dataset."""
from __future__ import annotations

import json

from abacus.cli.common import add_output_options, check_output

HELP = "detect, locate and count targets in a dataset"


def add_parser(sub):
    c = sub.add_parser("count", help=HELP)
    c.add_argument("input", help="dataset (.nc or .zarr); imaged first if needed")
    c.add_argument("-o", "--output", help="output dataset with detections and counts")
    c.add_argument("--settings", metavar="YAML", help="processing settings (default: the scene's)")
    c.add_argument("--json", action="store_true", help="print one JSON object: per-ping counts and summary")
    c.add_argument("--plots", metavar="DIR", help="detections over fan-beam images, counts vs ping")
    c.add_argument("--csv", metavar="FILE", help="write the detections table as CSV")
    c.add_argument("--targets-csv", metavar="FILE",
                   help="write the single targets with TS_comp/TS_uncomp, angles and positions as CSV")
    add_output_options(c)
    c.set_defaults(func=command)


def command(args) -> int:
    import processing
    from processing.base.dataset import open_tree, write_tree
    out = check_output(args.output, overwrite=args.overwrite) if args.output else None
    csv = check_output(args.csv, overwrite=args.overwrite, option="--csv") if args.csv else None
    tcsv = (check_output(args.targets_csv, overwrite=args.overwrite, option="--targets-csv")
            if args.targets_csv else None)
    plots = check_output(args.plots, overwrite=args.overwrite, option="--plots", folder=True) if args.plots else None
    tree = processing.count(open_tree(args.input, max_memory_gb=args.max_memory, work_factor=3.0),
                            args.settings)
    result = processing.count_summary(tree)
    if out is not None:
        write_tree(tree, out)
    if csv is not None:
        processing.write_csv(tree, csv)
    if tcsv is not None:
        from processing.backscatter.target_table import write_single_targets_csv
        write_single_targets_csv(tree, tcsv, args.settings)
    if plots is not None:
        from processing.base.atomic import staged
        from abacus.figures.plots import count_figures
        n = tree["Processing/Counts"].sizes["ping_time"]
        with staged(plots) as tmp:
            count_figures(tree, tmp, pings=range(min(n, 5)))
    if args.json:
        print(json.dumps(result))
    else:
        print(processing.format_counts(result))
        for what, where in (("dataset", args.output), ("detections CSV", args.csv),
                            ("single targets CSV", args.targets_csv), ("plots", args.plots)):
            if where:
                print(f"wrote {what}: {where}")
    return 0
