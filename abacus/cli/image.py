"""``abacus image``: pulse compression, beamforming and interferometry of a dataset."""
from __future__ import annotations

from abacus.cli.common import UsageError, add_output_options, check_output

HELP = "pulse compression, beamforming, interferometry of a dataset"


def add_parser(sub):
    i = sub.add_parser("image", help=HELP)
    i.add_argument("input", help="dataset (.nc or .zarr)")
    i.add_argument("-o", "--output", help="output dataset with /Processing added")
    i.add_argument("--plots", metavar="DIR", help="write PNG figures into DIR")
    i.add_argument("--settings", metavar="YAML", help="processing settings (default: the scene's)")
    i.add_argument("--ping", type=int, default=0, help="ping to plot (index in the file)")
    i.add_argument("--images", choices=["full", "native"], default="full",
                   help="store every interpolated row (default) or the data's own range sampling")
    add_output_options(i)
    i.set_defaults(func=command)


def command(args) -> int:
    import processing
    from processing.base.dataset import open_tree, tree_pings, write_tree
    if not args.output and not args.plots:
        raise UsageError("abacus image: give -o OUT and/or --plots DIR")
    out = check_output(args.output, overwrite=args.overwrite) if args.output else None
    plots = (check_output(args.plots, overwrite=args.overwrite, option="--plots", folder=True)
             if args.plots else None)
    tree = open_tree(args.input, max_memory_gb=args.max_memory, work_factor=6.0)
    n = tree_pings(tree)
    if not 0 <= args.ping < max(n, 1):
        raise UsageError(f"--ping {args.ping}: the dataset has pings 0..{n - 1} (indices in the file)")
    out_tree = processing.image(tree, args.settings, storage=args.images)
    if out is not None:
        write_tree(out_tree, out)
        print(f"wrote {out}")
    if plots is not None:
        from processing.base.atomic import staged
        from abacus.figures.plots import image_figures
        from processing.records import figure_images
        with staged(plots) as tmp:
            image_figures(figure_images(out_tree, [args.ping]), tmp, ping=args.ping)
        print(f"wrote figures into {plots}/")
    return 0
