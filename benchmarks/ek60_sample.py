"""Make the EK60 sample of tests/data from a public Simrad EK60 recording, in echopype's own
environment (echopype is not an abacus dependency):

    /path/to/echopype-venv/bin/python benchmarks/ek60_sample.py RAW [--channel-frequency 38000] [--pings 20]

RAW is ``DY1201_EK60-D20120214-T231011.raw`` of the pyEcholab repository (CI-CMG/pyEcholab,
commit bc6b89d, ``examples/data/``, MIT licence; NOAA cruise DY1201). The script converts it with
``echopype.open_raw(..., sonar_model="EK60")``, keeps one channel and the first pings in every
group, writes the result with echopype's own ``to_netcdf`` layout, reopens it with
``echopype.open_converted`` and stores echopype's ``compute_Sv`` of it beside it (checking it
equals ``compute_Sv`` of the whole recording on the same samples):

    tests/data/ek60_DY1201_38kHz.nc        the trimmed echopype file
    tests/data/ek60_DY1201_38kHz_Sv.npz    Sv (dB re 1 m-1) and echo_range (m) per ping and sample,
                                           echopype's version
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _trim(tree, channel: str, n_pings: int):
    """Every node of an echopype tree with one channel and the times of the first pings."""
    import numpy as np
    import xarray as xr
    bg = tree["Sonar/Beam_group1"].to_dataset()
    times = bg["ping_time"].values[:n_pings]
    lo, hi = times[0], times[-1]
    out = {}
    for node in tree.subtree:
        ds = node.to_dataset(inherit=False)
        if "channel" in ds.dims:
            ds = ds.sel(channel=[channel])
        for dim in list(ds.dims):
            if dim == "ping_time":
                ds = ds.isel(ping_time=slice(0, n_pings))
            elif ds[dim].dtype.kind == "M" and dim != "ping_time":
                t = ds[dim].values
                keep = np.flatnonzero((t >= lo) & (t <= hi))
                if keep.size == 0:              # the nearest time before the first ping
                    keep = np.array([max(int(np.searchsorted(t, lo)) - 1, 0)])
                ds = ds.isel({dim: keep})
        out[node.path] = ds
    return xr.DataTree.from_dict(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("raw")
    ap.add_argument("--channel-frequency", type=float, default=38000.0)
    ap.add_argument("--pings", type=int, default=20)
    ap.add_argument("--out", default=str(ROOT / "tests" / "data" / "ek60_DY1201_38kHz"))
    args = ap.parse_args(argv)
    import numpy as np
    import echopype as ep
    import xarray as xr

    ed = ep.open_raw(args.raw, sonar_model="EK60")
    full = ep.calibrate.compute_Sv(ed).compute()
    bg = ed["Sonar/Beam_group1"]
    k = int(np.argmin(np.abs(bg["frequency_nominal"].values - args.channel_frequency)))
    channel = str(bg["channel"].values[k])
    with tempfile.TemporaryDirectory() as tmp:
        ed.to_netcdf(Path(tmp) / "full.nc")
        tree = xr.open_datatree(Path(tmp) / "full.nc").load()
    small = _trim(tree, channel, args.pings)
    nc = Path(args.out + ".nc")
    comp = {v: {"zlib": True, "complevel": 9} for v in ("backscatter_r", "angle_athwartship", "angle_alongship")}
    small.to_netcdf(nc, engine="netcdf4", encoding={"/Sonar/Beam_group1": comp})
    ed2 = ep.open_converted(str(nc))
    sv = ep.calibrate.compute_Sv(ed2).compute()
    a = sv["Sv"].sel(channel=channel).values
    b = full["Sv"].sel(channel=channel).isel(ping_time=slice(0, args.pings)).values
    same = np.allclose(a, b, equal_nan=True, rtol=0, atol=1e-9)
    np.savez_compressed(args.out + "_Sv.npz", Sv=a.astype(np.float64),
                        echo_range=sv["echo_range"].sel(channel=channel).values.astype(np.float64),
                        ping_time=sv["ping_time"].values.astype("datetime64[ns]").astype(np.int64),
                        echopype_version=np.array(ep.__version__), channel=np.array(channel),
                        source=np.array(Path(args.raw).name))
    print(f"wrote {nc} ({nc.stat().st_size} bytes) and {args.out}_Sv.npz: channel {channel!r}, "
          f"{a.shape[0]} pings x {a.shape[1]} samples, echopype {ep.__version__}; trimmed file's "
          f"Sv equal to the whole recording's: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
