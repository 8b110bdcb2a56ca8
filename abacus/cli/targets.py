"""``abacus targets``: single-target detection by the echosounder criteria, with TS."""
from __future__ import annotations

from abacus.cli.common import add_output_options, check_outputs

HELP = "single targets by the echosounder criteria (echo length, phase deviation, beam compensation, TS)"


def add_parser(sub):
    c = sub.add_parser("targets", help=HELP)
    c.add_argument("input", help="dataset (.nc or .zarr) with samples; detected first if needed")
    c.add_argument("--settings", metavar="YAML",
                   help="processing settings (default: the scene's); the single_target: section "
                        "sets the criteria")
    c.add_argument("--csv", metavar="TABLE",
                   help="write every candidate as CSV: position, TS_uncomp/TS_comp, echo length, "
                        "phase and angle deviation, and the rule that rejected it")
    c.add_argument("--accepted-only", action="store_true",
                   help="with --csv: write the single targets only")
    c.add_argument("--json", action="store_true", help="print one JSON object: counts per rule and TS summary")
    add_output_options(c)
    c.set_defaults(func=command)


def summary(table) -> dict:
    """Counts per rule, the criteria (SONAR-netCDF4 2.0 names) and the single targets' TS."""
    import numpy as np

    from processing.backscatter.echo_criteria import RULES
    rule = table["rejected_by"].values.astype(str)
    single = rule == ""
    ts = table["ts_comp_db"].values[single]
    ts = ts[np.isfinite(ts)]
    return {"candidates": int(rule.size), "single_targets": int(single.sum()),
            "rejected_by": {r: int(np.count_nonzero(rule == r)) for r in RULES},
            "parameters": {k: v for k, v in table.attrs.items() if k.startswith("param_")},
            "nominal_echo_length_m": table.attrs.get("nominal_echo_length_m"),
            "ts_comp_mean_db": (float(10 * np.log10(np.mean(10 ** (ts / 10)))) if ts.size else None),
            "ts_comp_median_db": float(np.median(ts)) if ts.size else None}


def command(args) -> int:
    import processing
    from processing.backscatter.target_table import write_targets_csv
    from processing.base.dataset import open_tree
    (csv,) = check_outputs(args, [("--csv", args.csv, False)], inputs=[args.input, args.settings])
    tree = open_tree(args.input, max_memory_gb=args.max_memory, work_factor=3.0)
    table = processing.single_targets(tree, args.settings)
    if csv is not None:
        write_targets_csv(table, csv, accepted_only=args.accepted_only)
    result = summary(table)
    if args.json:
        from processing.tracking.tracks import strict_json
        print(strict_json(result))
    else:
        print(f"{result['single_targets']} single targets of {result['candidates']} candidates"
              + (f"; TS_comp mean {result['ts_comp_mean_db']:.2f} dB (linear mean), median "
                 f"{result['ts_comp_median_db']:.2f} dB" if result["ts_comp_mean_db"] is not None else ""))
        for rule, n in result["rejected_by"].items():
            if n:
                print(f"  rejected by {rule}: {n}")
        if csv is not None:
            print(f"wrote single targets CSV: {csv}")
    return 0
