"""``abacus count``: detect, locate and count the targets of a dataset."""
from __future__ import annotations

from abacus.cli.common import add_output_options, check_outputs, save_tree

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
    from processing.base.atomic import staged_set
    from processing.base.dataset import open_tree
    out, csv, tcsv, plots = check_outputs(
        args, [("-o", args.output, False), ("--csv", args.csv, False),
               ("--targets-csv", args.targets_csv, False), ("--plots", args.plots, True)],
        inputs=[args.input, args.settings])
    tree = processing.count(open_tree(args.input, max_memory_gb=args.max_memory, work_factor=3.0),
                            args.settings)
    result = processing.count_summary(tree)
    # every output to a temporary, all renamed into place at the end: an error, a full disk
    # or an interrupt part-way leaves none of them
    with staged_set() as outputs:
        if out is not None:
            save_tree(tree, outputs.path(out), final=out)
        if csv is not None:
            processing.write_csv(tree, outputs.path(csv))
        if tcsv is not None:
            from processing.backscatter.target_table import write_single_targets_csv
            write_single_targets_csv(tree, outputs.path(tcsv), args.settings)
        if plots is not None:
            from abacus.figures.plots import count_figures
            from processing.base.contract import COUNTS_GROUP
            from processing.base.dataset import group_of
            n = group_of(tree, COUNTS_GROUP).sizes["ping_time"]
            tmp = outputs.path(plots)
            tmp.mkdir()
            count_figures(tree, tmp, pings=range(min(n, 5)))
    if args.json:
        from processing.tracking.tracks import strict_json
        print(strict_json(result))
    else:
        print(processing.format_counts(result))
        for what, where in (("dataset", args.output), ("detections CSV", args.csv),
                            ("single targets CSV", args.targets_csv), ("plots", args.plots)):
            if where:
                print(f"wrote {what}: {where}")
    return 0
