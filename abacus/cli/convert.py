"""``abacus convert``: bring another layout to SONAR-netCDF4 (the previous abacus layout, MATLAB
.mat recordings of per-element samples, Simrad EK60/EK80 files converted by echopype: checked and
written back as they are, for ``abacus sv``)."""
from __future__ import annotations

from abacus.cli.common import (DATASET_FORMATS, SONAR_NETCDF2, UsageError, add_output_options, check_output, dataset_format,
                               save_tree)

HELP = ("convert the previous abacus layout, a MATLAB .mat recording or a SONAR-netCDF4 2.0 file to SONAR-netCDF4; check a Simrad "
        "EK60/EK80 file converted by echopype")


def add_parser(sub):
    c = sub.add_parser("convert", help=HELP)
    c.add_argument("input", help="a .mat file, or a .nc/.zarr dataset: the previous abacus layout, a "
                                 "SONAR-netCDF4 2.0 file, a Simrad EK60/EK80 file converted by echopype, or "
                                 "SONAR-netCDF4 of per-element samples")
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
    from processing.base.convert import open_record
    from processing.base.echosounder import echosounder_model
    from processing.base.files import FileRefused, check_file
    src = Path(args.input)
    out = check_output(args.output, overwrite=args.overwrite, inputs=[args.input])
    suffix = src.suffix.lower()
    if suffix not in (".mat", ".nc", ".zarr", ".h5", ".nc4"):
        raise UsageError(f"{src}: accepted inputs are .mat (MATLAB v5/v7) and .nc/.zarr datasets (the "
                         f"previous abacus layout, SONAR-netCDF4 2.0, Simrad EK60/EK80 files converted by "
                         f"echopype, SONAR-netCDF4)")
    try:   # a regular file (or a Zarr folder), before anything opens it: a FIFO would hang
        check_file(src, max_bytes=None, what="input", accepts="a .mat file or a .nc/.zarr dataset",
                   allow_folder=suffix == ".zarr")
    except FileRefused as exc:
        raise UsageError(str(exc)) from None
    fmt = dataset_format(out, args.format)
    tree = open_record(src, max_memory_gb=args.max_memory, beam_group=args.beam_group)
    model = echosounder_model(tree)
    if model is not None and fmt == SONAR_NETCDF2:
        raise UsageError(f"{src}: a {model} file as echopype converted it is checked and written back as "
                         f"SONAR-netCDF4 1.0 only; --format sonar-netcdf4-2 writes per-element records")
    from processing.base.dataset import ELEMENT_GROUP, group_of
    n = group_of(tree, ELEMENT_GROUP).sizes
    with staged_set() as outputs:
        save_tree(tree, outputs.path(out), final=out, fmt=fmt)
    if model is not None:
        print(f"wrote {out}: {model} file as echopype converted it, {n['channel']} channel(s), {n['ping_time']} "
              f"ping(s), {n['range_sample']} samples per ping (SONAR-netCDF4 1.0; `abacus sv` calibrates it)")
    else:
        print(f"wrote {out}: {n['ping_time']} ping(s), {n['beam']} element(s), {n['range_sample']} samples "
              f"per ping (SONAR-netCDF4 {'2.0' if fmt == SONAR_NETCDF2 else '1.0'})")
    return 0
