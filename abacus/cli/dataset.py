"""``abacus dataset``: randomised scenes, their images and label cubes, as training data."""
from __future__ import annotations

from abacus.cli.common import Progress, UsageError, add_output_options, check_outputs
from acoustics.seeds import SEED_MAX

HELP = "draw N randomised scenes and write their images with label cubes (training data)"


def add_parser(sub):
    d = sub.add_parser("dataset", help=HELP,
                       description="Draw N scenes (school size, density, range and depth, sea state, "
                                   "floor depth) from a distribution seeded by --seed, simulate each "
                                   "with its arrivals, image it and label every cell; write "
                                   "sample_NNNNN.npz (+ its scene .yaml) and index.csv into OUT "
                                   "(docs/training.md).")
    d.add_argument("-o", "--output", metavar="OUT", required=True, help="a new folder")
    d.add_argument("--scenes", type=int, required=True, help="number of scenes to draw")
    d.add_argument("--seed", type=int, default=0, help="seed of the distribution (default 0)")
    d.add_argument("--pings", type=int, default=1, help="pings per scene (default 1)")
    add_output_options(d, memory=False)
    d.set_defaults(func=command)


def command(args) -> int:
    from abacus.training import make_dataset
    from processing.base.atomic import staged_set
    if not 1 <= args.scenes <= 1_000_000:
        raise UsageError(f"--scenes must be an integer in [1, 1000000], got {args.scenes}")
    if not 1 <= args.pings <= 10_000:
        raise UsageError(f"--pings must be an integer in [1, 10000], got {args.pings}")
    if not 0 <= args.seed <= SEED_MAX:
        raise UsageError(f"--seed must be an integer in [0, {SEED_MAX}], got {args.seed}")
    (out,) = check_outputs(args, [("-o", args.output, True)])
    with staged_set() as outputs:
        tmp = outputs.path(out)
        tmp.mkdir()
        make_dataset(tmp, args.scenes, args.seed, pings=args.pings, progress=Progress("dataset"))
    print(f"wrote {out}/: {args.scenes} sample(s) (sample_NNNNN.npz, .yaml) and index.csv")
    return 0
