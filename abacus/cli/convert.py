"""``abacus convert``: bring another layout to SONAR-netCDF4 (the previous abacus layout, MATLAB
.mat recordings of per-element samples)."""
from __future__ import annotations

from abacus.cli.common import (DATASET_FORMATS, SONAR_NETCDF2, UsageError, add_output_options, check_output, dataset_format,
                               save_tree)

HELP = "convert the previous abacus layout or a MATLAB .mat recording to SONAR-netCDF4"


def add_parser(sub):
    c = sub.add_parser("convert", help=HELP)
    c.add_argument("input", help="a .nc/.zarr dataset in the previous abacus layout, a SONAR-netCDF4 2.0 "
                                 "file (.nc), or a .mat file")
    c.add_argument("output", help="the SONAR-netCDF4 dataset to write (.nc or .zarr)")
    c.add_argument("--format", choices=DATASET_FORMATS,
                   help="netcdf or zarr: SONAR-netCDF4 1.0 (default, from the suffix); sonar-netcdf4-2: "
                        "SONAR-netCDF4 2.0 (.nc; docs/dataset.md)")
    c.add_argument("--beam-group", default="Beam_group1",
                   help="the beam group of a SONAR-netCDF4 2.0 input to read (default Beam_group1; an "
                        "EK80 writes one per channel)")
    add_output_options(c)
    c.set_defaults(func=command)


def command(args) -> int:
    from pathlib import Path

    from processing.base.atomic import staged_set
    from processing.base.contract import LEGACY_ELEMENT_GROUP
    from processing.base.convert import from_legacy, open_record, read_mat
    from processing.base.dataset import has_group, open_tree
    from processing.base.files import FileRefused, check_file
    from processing.base.sonar_netcdf2 import is_sonar_netcdf2
    src = Path(args.input)
    out = check_output(args.output, overwrite=args.overwrite, inputs=[args.input])
    suffix = src.suffix.lower()
    if suffix not in (".mat", ".nc", ".zarr", ".h5", ".nc4"):
        raise UsageError(f"{src}: accepted inputs are .mat (MATLAB v5/v7), SONAR-netCDF4 2.0 files (.nc) "
                         f"and .nc/.zarr datasets in the previous abacus layout")
    try:   # a regular file (or a Zarr folder), before anything opens it: a FIFO would hang
        check_file(src, max_bytes=None, what="input", accepts="a .mat file or a .nc/.zarr dataset",
                   allow_folder=suffix == ".zarr")
    except FileRefused as exc:
        raise UsageError(str(exc)) from None
    fmt = dataset_format(out, args.format)
    if suffix == ".mat":
        tree = read_mat(src, max_memory_gb=args.max_memory)
    elif is_sonar_netcdf2(src):
        tree = open_record(src, max_memory_gb=args.max_memory, beam_group=args.beam_group)
    else:
        tree = open_tree(src, max_memory_gb=args.max_memory, work_factor=2.0)
        # a 1.0 dataset is written as 2.0 as it is; anything else must be the previous layout
        if fmt != SONAR_NETCDF2 or has_group(tree, LEGACY_ELEMENT_GROUP):
            tree = from_legacy(tree, source=str(src))
    n = tree["Sonar/Beam_group1"].ds.sizes
    with staged_set() as outputs:
        save_tree(tree, outputs.path(out), final=out, fmt=fmt)
    print(f"wrote {out}: {n['ping_time']} ping(s), {n['beam']} element(s), {n['range_sample']} samples "
          f"per ping (SONAR-netCDF4 {'2.0' if fmt == SONAR_NETCDF2 else '1.0'})")
    return 0
