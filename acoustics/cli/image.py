"""``abacus image``: pulse compression, beamforming and interferometry of a dataset."""
from __future__ import annotations

from pathlib import Path

from acoustics.cli.common import UsageError

HELP = "pulse compression, beamforming, interferometry of a dataset"


def add_parser(sub):
    i = sub.add_parser("image", help=HELP)
    i.add_argument("input", help="dataset (.nc or .zarr)")
    i.add_argument("-o", "--output", help="output dataset with /Processing added")
    i.add_argument("--plots", metavar="DIR", help="write PNG figures into DIR")
    i.add_argument("--settings", metavar="YAML", help="processing settings (default: the scene's)")
    i.add_argument("--ping", type=int, default=0, help="ping to plot (index in the file)")
    i.set_defaults(func=command)


def command(args) -> int:
    import processing
    from processing.dataset import open_tree, write_tree
    if not args.output and not args.plots:
        raise UsageError("abacus image: give -o OUT and/or --plots DIR")
    tree = open_tree(args.input)
    out_tree = processing.image(tree, args.settings)
    if args.output:
        write_tree(out_tree, Path(args.output))
        print(f"wrote {args.output}")
    if args.plots:
        from processing.plots import image_figures
        from processing.products import figure_images
        for p in image_figures(figure_images(out_tree, [args.ping]), Path(args.plots), ping=0):
            print(f"wrote {p}")
    return 0
