"""``abacus simulate``: a scene's per-element echoes into a dataset."""
from __future__ import annotations

import sys
from pathlib import Path

from abacus.cli.common import (DATASET_FORMATS, Progress, UsageError, add_output_options, check_output,
                                  check_scene_resources, dataset_format, load, ping_list, save_tree)
from acoustics.seeds import SEED_MAX

HELP = "simulate a scene's per-element echoes into a dataset"


def add_parser(sub):
    m = sub.add_parser("simulate", help=HELP)
    m.add_argument("scene", help="scene file (YAML) or a built-in scene's name")
    m.add_argument("-o", "--output", required=True, help="output file (.nc) or folder (.zarr)")
    m.add_argument("--pings", type=int, help="number of pings (default: the scene's)")
    m.add_argument("--seed", type=int, help="seed (default: the scene's)")
    m.add_argument("--format", choices=DATASET_FORMATS,
                   help="netcdf or zarr: SONAR-netCDF4 1.0 (default, from the suffix; what echopype "
                        "opens); sonar-netcdf4-2: SONAR-netCDF4 2.0 (.nc; docs/dataset.md)")
    m.add_argument("--arrivals", action="store_true",
                   help="also write every path of every ping, /Vendor_specific/Arrivals "
                        "(docs/dataset.md, 'Arrivals'; the scene's effects.arrivals.floor_db applies)")
    add_output_options(m)
    m.set_defaults(func=command)


def command(args) -> int:
    from acoustics.simulation.run import simulate
    from processing.base.atomic import staged_set
    from processing.base.dataset import ELEMENT_GROUP
    scene = load(args.scene)
    out = check_output(args.output, overwrite=args.overwrite,
                       inputs=[args.scene] if Path(args.scene).exists() else [])
    fmt = dataset_format(out, args.format)
    if args.seed is not None and not 0 <= args.seed <= SEED_MAX:
        raise UsageError(f"--seed must be an integer in [0, {SEED_MAX}], got {args.seed}")
    pings = ping_list(scene, args.pings)
    check_scene_resources(scene, args, pings=len(pings) if pings else None, process=False, output=out)
    tree = simulate(scene, pings=pings, seed=args.seed,
                    progress=Progress("simulate"), arrivals=True if args.arrivals else None)
    with staged_set() as outputs:
        save_tree(tree, outputs.path(out), final=out, fmt=fmt)
    from processing.base.contract import ARRIVALS_GROUP
    from processing.base.dataset import group_of, stage_seconds
    n_p = tree[ELEMENT_GROUP].sizes["ping_time"]
    table = group_of(tree, ARRIVALS_GROUP)
    arrivals = "" if table is None else f", {table.sizes['arrival']} arrival(s)"
    print(f"wrote {out} ({fmt}): {n_p} ping(s){arrivals}; stages: "
          + ", ".join(f"{s} {t:.2f} s" for s, t in stage_seconds(tree).items()))
    clipped = tree[ELEMENT_GROUP].ds.get("adc_clipped_samples")
    if clipped is not None and int(clipped.sum()):
        print(f"warning: the ADC clipped {int(clipped.sum())} samples", file=sys.stderr)
    return 0
