"""``abacus sv``: calibrated volume backscattering — MVBS grid, NASC of layers, CSV exports."""
from __future__ import annotations

import json

from abacus.cli.common import UsageError, add_output_options, check_output

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
        if not b > a >= 0:
            raise UsageError(f"--layer {t!r}: STOP must exceed START, both ≥ 0 m")
        out.append((a, b))
    return out


def command(args) -> int:
    import numpy as np

    from processing.base.dataset import open_tree, write_tree
    from processing.backscatter.sv import SV_GROUP, backscatter, write_mvbs_csv, write_nasc_csv
    if not args.range_bin > 0 or args.ping_bin < 1:
        raise UsageError("--range-bin must be positive (m) and --ping-bin at least 1")
    layers = _layers(args.layer)
    out = check_output(args.output, overwrite=args.overwrite) if args.output else None
    csv = check_output(args.csv, overwrite=args.overwrite, option="--csv") if args.csv else None
    ncsv = check_output(args.nasc_csv, overwrite=args.overwrite, option="--nasc-csv") if args.nasc_csv else None
    tree = backscatter(open_tree(args.input, max_memory_gb=args.max_memory, work_factor=3.0),
                       args.settings, range_bin_m=args.range_bin, ping_bin=args.ping_bin, layers_m=layers)
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
    if out is not None:
        write_tree(tree, out)
    if csv is not None:
        write_mvbs_csv(tree, csv)
    if ncsv is not None:
        write_nasc_csv(tree, ncsv)
    if args.json:
        print(json.dumps(summary))
    else:
        g = summary["grid"]
        print(f"MVBS: {g['ping_bins']} ping bin(s) x {g['range_bins']} range bin(s) x {g['beams']} beams; "
              f"mean Sv {summary['Sv_mean_db'] if summary['Sv_mean_db'] is None else round(summary['Sv_mean_db'], 2)} dB re 1 m⁻¹ "
              f"(noise σ {summary['noise_sigma_counts']:.4g} counts subtracted)")
        for lay in summary["layers"]:
            a, b = lay["range_m"]
            print(f"NASC {a:.2f}–{b:.2f} m: {lay['NASC_mean_m2_nmi2']:.4g} m² nmi⁻² (mean over pings and beams)")
        for what, where in (("dataset", args.output), ("MVBS CSV", args.csv), ("NASC CSV", args.nasc_csv)):
            if where:
                print(f"wrote {what}: {where}")
    return 0
