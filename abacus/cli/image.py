"""``abacus image``: pulse compression, beamforming and interferometry of a dataset."""
from __future__ import annotations

from abacus.cli.common import UsageError, add_output_options, check_outputs, save_tree

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
    from processing.base.atomic import staged_set
    from processing.base.dataset import open_tree, tree_pings
    if not args.output and not args.plots:
        raise UsageError("abacus image: give -o OUT and/or --plots DIR")
    out, plots = check_outputs(args, [("-o", args.output, False), ("--plots", args.plots, True)],
                               inputs=[args.input, args.settings])
    tree = open_tree(args.input, max_memory_gb=args.max_memory, work_factor=6.0)
    n = tree_pings(tree)
    if not 0 <= args.ping < max(n, 1):
        raise UsageError(f"--ping {args.ping}: the dataset has pings 0..{n - 1} (indices in the file)")
    out_tree = processing.image(tree, args.settings, storage=args.images)
    # both outputs to temporaries, renamed into place together at the end
    with staged_set() as outputs:
        if out is not None:
            save_tree(out_tree, outputs.path(out), final=out)
        if plots is not None:
            from abacus.figures.plots import image_figures
            from processing.records import figure_images
            tmp = outputs.path(plots)
            tmp.mkdir()
            image_figures(figure_images(out_tree, [args.ping]), tmp, ping=args.ping, tree=out_tree)
    if out is not None:
        print(f"wrote {out}")
    if plots is not None:
        print(f"wrote figures into {plots}/")
    return 0
