"""``abacus sv``: calibrated volume backscattering — MVBS grid, NASC of layers, CSV exports."""
from __future__ import annotations

import math

from abacus.cli.common import UsageError, add_output_options, check_outputs, save_tree

HELP = "volume backscattering: Sv gridded means (MVBS) and NASC of range layers"


def add_parser(sub):
    c = sub.add_parser("sv", help=HELP)
    c.add_argument("input", help="dataset (.nc or .zarr) with samples and a calibration")
    c.add_argument("-o", "--output", help="output dataset with /Processing/Sv")
    c.add_argument("--settings", metavar="YAML", help="processing settings (default: the scene's)")
    c.add_argument("--range-bin", type=float, default=0.5, metavar="M", help="MVBS bin height (m), default 0.5")
    c.add_argument("--ping-bin", type=int, default=10, metavar="N", help="pings per MVBS bin, default 10")
    c.add_argument("--layer", action="append", metavar="START:STOP",
                   help="a NASC range layer in m (repeatable); default the image's range")
    c.add_argument("--csv", metavar="FILE", help="MVBS cells as CSV")
    c.add_argument("--nasc-csv", metavar="FILE", help="NASC per ping, layer and beam as CSV")
    c.add_argument("--cells", action="store_true",
                   help="keep every cell's Sv (dB) and linear s_v in /Processing/Sv (always for a Simrad record)")
    c.add_argument("--cells-csv", metavar="FILE", help="every cell's Sv (dB) and linear s_v as CSV (implies --cells)")
    c.add_argument("--echopype", metavar="FILE",
                   help="the calibrated image in the EK60's convention, for echopype's open_converted, "
                        "combine_echodata and compute_Sv (docs/interop.md)")
    c.add_argument("--empty", choices=("blank", "-999"), default="blank",
                   help="a CSV cell without Sv: blank (default) or -999, as Echoview writes it")
    c.add_argument("--json", action="store_true", help="print one JSON object: layer NASC and mean Sv")
    add_output_options(c)
    c.set_defaults(func=command)


def _layers(texts):
    if not texts:
        return None
    out = []
    for t in texts:
        try:
            a, b = (float(x) for x in t.split(":"))
        except ValueError:
            raise UsageError(f"--layer {t!r}: expected START:STOP in metres, e.g. 15:20") from None
        if not (math.isfinite(a) and math.isfinite(b) and b > a >= 0):
            raise UsageError(f"--layer {t!r}: STOP must exceed START, both finite and ≥ 0 m")
        out.append((a, b))
    return out


def _check_grid_bound(tree, args) -> None:
    """Refuse a range bin that makes the MVBS grid too large before imaging: a lower bound of
    its memory (one beam, the record's whole range) against the limit; the exact check, with the
    image's beams and range, follows in processing.backscatter.sv."""
    from processing.base.dataset import ELEMENT_GROUP, ENVIRONMENT_GROUP, group_of
    from processing.base.resources import Estimate, check_resources
    eg, env = group_of(tree, ELEMENT_GROUP), group_of(tree, ENVIRONMENT_GROUP)
    try:
        n_s = int(eg.sizes["range_sample"])
        n_p = int(eg.sizes["ping_time"])
        dt = float(eg["sample_interval"].values.ravel()[0])
        c = float(env["sound_speed_indicative"].values)
    except (AttributeError, KeyError, IndexError, TypeError, ValueError):
        return                                   # the reader names what is missing
    span = n_s * dt * c / 2
    if not (span > 0 and span < 1e9):
        return
    n_bins = span / args.range_bin + 1
    grid = -(-n_p // args.ping_bin) * n_bins * 8.0 * 6
    check_resources(Estimate(grid, 0.0, [("MVBS grid", grid)],
                             keys=f"the MVBS range bins (--range-bin {args.range_bin:g} m over up to {span:.3g} m: "
                                  f"{n_bins:.3g} bins per beam; give a larger --range-bin)"),
                    what=f"abacus sv --range-bin {args.range_bin:g}", max_memory_gb=args.max_memory)


def command(args) -> int:
    import numpy as np

    from processing.base.atomic import staged_set
    from processing.base.dataset import open_tree
    from processing.backscatter.sv import (SV_GROUP, LayerError, backscatter, write_cells_csv, write_mvbs_csv,
                                           write_nasc_csv)
    if not (math.isfinite(args.range_bin) and args.range_bin > 0) or args.ping_bin < 1:
        raise UsageError("--range-bin must be a positive number of metres and --ping-bin at least 1")
    layers = _layers(args.layer)
    out, csv, ncsv, ccsv, epv = check_outputs(
        args, [("-o", args.output, False), ("--csv", args.csv, False), ("--nasc-csv", args.nasc_csv, False),
               ("--cells-csv", args.cells_csv, False), ("--echopype", args.echopype, False)],
        inputs=[args.input, args.settings])
    tree = open_tree(args.input, max_memory_gb=args.max_memory, work_factor=3.0)
    _check_grid_bound(tree, args)
    try:
        tree = backscatter(tree, args.settings, range_bin_m=args.range_bin, ping_bin=args.ping_bin,
                           layers_m=layers, max_memory_gb=args.max_memory,
                           cells=bool(args.cells or args.cells_csv or args.echopype))
    except LayerError as exc:
        raise UsageError(f"--layer {args.layer[exc.layer]}: {exc}") from None
    ds = tree[SV_GROUP].ds
    lin = ds["s_v_mean"].values
    nasc = ds["NASC"].values
    summary = {"layers": [{"range_m": [float(a), float(b)],
                           "NASC_mean_m2_nmi2": float(np.mean(nasc[:, k])),
                           "NASC_per_beam_m2_nmi2": [float(x) for x in nasc[:, k].mean(0)]}
                          for k, (a, b) in enumerate(zip(ds["layer_start_m"].values, ds["layer_stop_m"].values))],
               "Sv_mean_db": (float(10 * np.log10(np.nanmean(lin))) if np.nanmean(lin) > 0 else None),
               "noise_sigma_counts": float(ds.attrs["noise_sigma_counts"]),
               "grid": {"ping_bins": int(lin.shape[0]), "range_bins": int(lin.shape[1]),
                        "beams": int(lin.shape[2])}}
    # every output to a temporary, all renamed into place at the end: an error, a full disk
    # or an interrupt part-way leaves none of them
    with staged_set() as outputs:
        if out is not None:
            save_tree(tree, outputs.path(out), final=out)
        if csv is not None:
            write_mvbs_csv(tree, outputs.path(csv), empty=args.empty)
        if ccsv is not None:
            write_cells_csv(tree, outputs.path(ccsv), empty=args.empty)
        if epv is not None:
            from processing.backscatter.echopype_view import echopype_view
            save_tree(echopype_view(tree, args.settings), outputs.path(epv), final=epv)
        if ncsv is not None:
            write_nasc_csv(tree, outputs.path(ncsv))
    if args.json:
        from processing.tracking.tracks import strict_json
        print(strict_json(summary))
    else:
        g = summary["grid"]
        how = (f"calibrated as an {ds.attrs['calibration'].split(':')[0]} record" if "calibration" in ds.attrs
               else f"noise σ {summary['noise_sigma_counts']:.4g} counts subtracted")
        print(f"MVBS: {g['ping_bins']} ping bin(s) x {g['range_bins']} range bin(s) x {g['beams']} beams; "
              f"mean Sv {summary['Sv_mean_db'] if summary['Sv_mean_db'] is None else round(summary['Sv_mean_db'], 2)} dB re 1 m⁻¹ "
              f"({how})")
        for lay in summary["layers"]:
            a, b = lay["range_m"]
            print(f"NASC {a:.2f}–{b:.2f} m: {lay['NASC_mean_m2_nmi2']:.4g} m² nmi⁻² (mean over pings and beams)")
        for what, where in (("dataset", args.output), ("MVBS CSV", args.csv), ("NASC CSV", args.nasc_csv),
                            ("cells CSV", args.cells_csv), ("echopype view (EK60 convention)", args.echopype)):
            if where:
                print(f"wrote {what}: {where}")
    return 0
