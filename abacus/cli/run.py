"""``abacus run``: the main job — simulate, image, detect, locate, count; dataset and figures.

The job is :func:`abacus.runs.run` (``abacus.run`` from Python); this command chooses how the
figures are drawn (a pool of one worker process where a core is spare, else in this process)
and prints what the run made.
"""
from __future__ import annotations

import argparse
import sys

from abacus.cli.common import Progress, add_output_options

_T0 = __import__("time").perf_counter()   # the command's own clock starts at its import

HELP = "the main job: simulate, image, detect, locate, count"


def add_parser(sub):
    r = sub.add_parser("run", help=HELP)
    r.add_argument("scene", help="scene file (YAML) or a built-in scene's name (e.g. default)")
    r.add_argument("-o", "--output", help="output folder (default runs/<scene name>)")
    r.add_argument("--pings", type=int, help="number of pings (default: the scene's)")
    r.add_argument("--plots", action=argparse.BooleanOptionalAction, default=True,
                   help="draw the figures (default; --no-plots: numbers only)")
    r.add_argument("--images", choices=["none", "native", "full"], default="none",
                   help="store the images in run.nc: none (default; they follow from the samples), "
                        "native (at the data's range sampling) or full (every interpolated row)")
    r.add_argument("--format", choices=["netcdf", "sonar-netcdf4-2"], default="netcdf",
                   help="netcdf (default): run.nc in SONAR-netCDF4 1.0; sonar-netcdf4-2: also "
                        "run.sonar-netcdf4-2.nc, SONAR-netCDF4 2.0 with the single targets and "
                        "gridded Sv (docs/dataset.md)")
    add_output_options(r)
    r.set_defaults(func=command)


def command(args) -> int:
    from contextlib import ExitStack

    import processing
    from abacus.runs import run

    with ExitStack() as stack:
        # the figures' drawing starts first: a pool's workers import matplotlib while this
        # process imports and simulates (abacus.figures.drawing)
        drawing = None
        if args.plots:
            drawing = stack.enter_context(figure_drawing(getattr(args, "standalone", False)))
        result = run(args.scene, args.output, pings=args.pings, plots=args.plots, images=args.images,
                     overwrite=args.overwrite, max_memory_gb=args.max_memory, drawing=drawing,
                     sonar_netcdf2=args.format == "sonar-netcdf4-2",
                     progress=Progress("simulate"), announce=print, started_s=_T0)
    print()
    print(processing.format_counts(result.summary))
    for note in result.notes:
        print(f"warning: {note}", file=sys.stderr)
    print(f"\noutputs in {result.folder}/: {', '.join(result.made)}")
    print(f"time: {result.stages.summary()} (start: interpreter and imports)")
    return 0


def figure_drawing(standalone: bool):
    """How ``abacus run`` draws its figures: in a pool of one worker process where the process
    is the command's own (``standalone``: not a program that called ``main(argv)``, whose
    script a "spawn" worker would run again) and has a second core for it (measured in
    docs/performance.md, "End to end"); else in this process."""
    from abacus.figures.drawing import Drawing, PoolDrawing
    from processing.base.resources import usable_cores
    return PoolDrawing(workers=1) if standalone and usable_cores() >= 2 else Drawing()
