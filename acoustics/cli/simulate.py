"""``abacus simulate``: a scene's per-element echoes into a dataset."""
from __future__ import annotations

import sys
from pathlib import Path

from acoustics.cli.common import Progress, UsageError, load, ping_list

HELP = "simulate a scene's per-element echoes into a dataset"


def add_parser(sub):
    m = sub.add_parser("simulate", help=HELP)
    m.add_argument("scene", help="scene file (YAML) or a built-in scene's name")
    m.add_argument("-o", "--output", required=True, help="output file (.nc) or folder (.zarr)")
    m.add_argument("--pings", type=int, help="number of pings (default: the scene's)")
    m.add_argument("--seed", type=int, help="seed (default: the scene's)")
    m.add_argument("--format", choices=["netcdf", "zarr"], help="default from the suffix")
    m.set_defaults(func=command)


def command(args) -> int:
    from acoustics.simulation.run import simulate
    from processing.dataset import ELEMENT_GROUP, write_tree
    scene = load(args.scene)
    out = Path(args.output)
    fmt = args.format or ("zarr" if out.suffix == ".zarr" else "netcdf")
    if args.seed is not None and args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}")
    tree = simulate(scene, pings=ping_list(scene, args.pings), seed=args.seed,
                    progress=Progress("simulate"))
    write_tree(tree, out, fmt=fmt)
    prov = tree["Provenance"].ds
    n_p = tree[ELEMENT_GROUP].sizes["ping_time"]
    print(f"wrote {out} ({fmt}): {n_p} ping(s); stages: "
          + ", ".join(f"{s} {t:.2f} s" for s, t in zip(prov["stage"].values, prov["stage_seconds"].values)))
    clipped = tree[ELEMENT_GROUP].ds.get("adc_clipped_samples")
    if clipped is not None and int(clipped.sum()):
        print(f"warning: the ADC clipped {int(clipped.sum())} samples", file=sys.stderr)
    return 0
