"""``abacus convert``: bring another layout to SONAR-netCDF4 (the previous abacus layout, MATLAB
.mat recordings of per-element samples)."""
from __future__ import annotations

from abacus.cli.common import UsageError, add_output_options, check_output, save_tree

HELP = "convert the previous abacus layout or a MATLAB .mat recording to SONAR-netCDF4"


def add_parser(sub):
    c = sub.add_parser("convert", help=HELP)
    c.add_argument("input", help="a .nc/.zarr dataset in the previous abacus layout, or a .mat file")
    c.add_argument("output", help="the SONAR-netCDF4 dataset to write (.nc or .zarr)")
    add_output_options(c)
    c.set_defaults(func=command)


def command(args) -> int:
    from pathlib import Path

    from processing.base.atomic import staged_set
    from processing.base.convert import from_legacy, read_mat
    from processing.base.dataset import open_tree
    from processing.base.files import FileRefused, check_file
    src = Path(args.input)
    out = check_output(args.output, overwrite=args.overwrite, inputs=[args.input])
    suffix = src.suffix.lower()
    if suffix not in (".mat", ".nc", ".zarr", ".h5", ".nc4"):
        raise UsageError(f"{src}: accepted inputs are .mat (MATLAB v5/v7) and .nc/.zarr datasets in "
                         f"the previous abacus layout")
    try:   # a regular file (or a Zarr folder), before anything opens it: a FIFO would hang
        check_file(src, max_bytes=None, what="input", accepts="a .mat file or a .nc/.zarr dataset",
                   allow_folder=suffix == ".zarr")
    except FileRefused as exc:
        raise UsageError(str(exc)) from None
    if suffix == ".mat":
        tree = read_mat(src, max_memory_gb=args.max_memory)
    else:
        tree = from_legacy(open_tree(src, max_memory_gb=args.max_memory, work_factor=2.0),
                           source=str(src))
    n = tree["Sonar/Beam_group1"].ds.sizes
    with staged_set() as outputs:
        save_tree(tree, outputs.path(out), final=out)
    print(f"wrote {out}: {n['ping_time']} ping(s), {n['beam']} element(s), {n['range_sample']} samples "
          f"per ping (SONAR-netCDF4 1.0)")
    return 0
