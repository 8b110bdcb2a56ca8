"""``abacus convert``: bring another layout to SONAR-netCDF4 (the previous abacus layout, MATLAB
.mat recordings of per-element samples)."""
from __future__ import annotations

from abacus.cli.common import UsageError, add_output_options, check_output

HELP = "convert the previous abacus layout or a MATLAB .mat recording to SONAR-netCDF4"


def add_parser(sub):
    c = sub.add_parser("convert", help=HELP)
    c.add_argument("input", help="a .nc/.zarr dataset in the previous abacus layout, or a .mat file")
    c.add_argument("output", help="the SONAR-netCDF4 dataset to write (.nc or .zarr)")
    add_output_options(c)
    c.set_defaults(func=command)


def command(args) -> int:
    from pathlib import Path

    from processing.base.convert import from_legacy, read_mat
    from processing.base.dataset import open_tree, write_tree
    src = Path(args.input)
    out = check_output(args.output, overwrite=args.overwrite)
    if not src.exists():
        raise UsageError(f"{src}: no such file or folder")
    if src.suffix.lower() == ".mat":
        tree = read_mat(src)
    elif src.suffix.lower() in (".nc", ".zarr", ".h5", ".nc4"):
        tree = from_legacy(open_tree(src, max_memory_gb=args.max_memory, work_factor=2.0).load(),
                           source=str(src))
    else:
        raise UsageError(f"{src}: accepted inputs are .mat (MATLAB v5/v7) and .nc/.zarr datasets in "
                         f"the previous abacus layout")
    n = tree["Sonar/Beam_group1"].ds.sizes
    write_tree(tree, out)
    print(f"wrote {out}: {n['ping_time']} ping(s), {n['beam']} element(s), {n['range_sample']} samples "
          f"per ping (SONAR-netCDF4 1.0)")
    return 0
