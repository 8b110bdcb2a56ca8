"""``abacus experiment``: Monte Carlo over pings and a sweep, in parallel (Dask); dataset and report."""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from abacus.cli.common import Progress, UsageError, load, ping_list

HELP = "Monte Carlo over pings and a sweep, in parallel (Dask); dataset and report"


def add_parser(sub):
    e = sub.add_parser("experiment", help=HELP)
    e.add_argument("scene", help="scene file (YAML) or a built-in scene's name")
    e.add_argument("-o", "--output", required=True, help="output folder (rerun to resume)")
    e.add_argument("--pings", type=int, help="number of pings (default: the scene's)")
    e.add_argument("--sweep", metavar="KEY=SPEC",
                   help="KEY=START:STOP:STEP or KEY=V1,V2,...; KEY a dotted scene path or 'threshold'")
    e.add_argument("--workers", type=int, help="local Dask worker processes; 0: in this process "
                   "(default: the fastest for this machine: in process up to 2 cores, else a local "
                   "cluster of 2-thread workers)")
    e.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, e.g. tcp://host:8786")
    e.add_argument("--format", choices=["netcdf", "zarr"], help="results format (default netcdf)")
    e.add_argument("--restart", action="store_true", help="discard finished pings of an earlier run in DIR")
    e.add_argument("--track-pings", type=int, metavar="N",
                   help="track runs of N consecutive pings (one task each) and score them as "
                        "`abacus track` does: HOTA, IDF1, MOTA per run, and the nMAE of the track "
                        "counts over the runs")
    e.set_defaults(func=command)


def command(args) -> int:
    from abacus.experiment import ExperimentError, parse_sweep, run_experiment
    scene = load(args.scene)
    try:
        sweep = parse_sweep(args.sweep) if args.sweep else None
        out = Path(args.output)
        fmt = args.format or "netcdf"
        t0 = time.perf_counter()
        path = run_experiment(scene, out, pings=ping_list(scene, args.pings), sweep=sweep,
                              workers=args.workers, scheduler=args.scheduler, fmt=fmt,
                              restart=args.restart, progress=Progress("experiment"),
                              track_pings=args.track_pings)
    except ExperimentError as exc:
        raise UsageError(str(exc)) from None
    import xarray as xr
    with xr.open_dataset(path, engine="zarr" if fmt == "zarr" else "netcdf4") as ds:
        base = ds.isel(setting=0)
        n = ds.sizes["ping"]
        print(f"{n} ping(s) x {ds.sizes['setting']} setting(s) in {time.perf_counter() - t0:.1f} s "
              f"({ds.attrs['tasks_run']} run, {ds.attrs['tasks_resumed']} resumed; "
              f"{ds.attrs['scheduler']}, workers {ds.attrs['workers']})")
        if np.isfinite(base["error_after"]).any():
            print(f"count error before interferometry {float(base['error_before'].mean()):+.2f} ± "
                  f"{float(base['error_before'].std()):.2f}, after {float(base['error_after'].mean()):+.2f}"
                  f" ± {float(base['error_after'].std()):.2f} targets per ping")
        if np.isfinite(ds["ts_estimate_db"].isel(setting=0)):
            line = f"TS from s_v and counted density: {float(ds['ts_estimate_db'].isel(setting=0)):.2f} dB"
            if np.isfinite(ds["ts_true_db"].isel(setting=0)):
                line += f" (true mean σ_bs: {float(ds['ts_true_db'].isel(setting=0)):.2f} dB)"
            print(line)
        if "track_count_nmae" in ds and np.isfinite(ds["track_count_nmae"].isel(setting=0)):
            b = ds.isel(setting=0)
            print(f"tracks over {ds.sizes['run']} run(s) of {int(ds.attrs['track_pings'])} pings: "
                  f"{int(b['run_counted_passages'].sum())} counted for "
                  f"{int(b['run_true_passages'].sum())} true passages, nMAE "
                  f"{float(b['track_count_nmae']):.3f}; HOTA {float(b['hota_mean']):.3f}, "
                  f"IDF1 {float(b['idf1_mean']):.3f}, MOTA {float(b['mota_mean']):.3f} (means over the runs)")
        for note in [n for n in str(ds.attrs.get("notes", "")).split("; ") if n]:
            print(f"warning: {note}", file=sys.stderr)
        if int(ds.attrs.get("parts_recomputed_damaged", 0)):
            print(f"note: {int(ds.attrs['parts_recomputed_damaged'])} damaged part(s) were recomputed",
                  file=sys.stderr)
    print(f"outputs in {out}/: {path.name}, report.html, figures/, parts/ (kept for resuming)")
    return 0
