"""Bit identity of the simulator across a change: dump every variable a set of scenes writes
(the provenance, which holds times, left out), then compare two dumps byte for byte.

    git checkout A && python benchmarks/bit_identity.py dump /tmp/a.npz
    git checkout B && python benchmarks/bit_identity.py dump /tmp/b.npz
    python benchmarks/bit_identity.py compare /tmp/a.npz /tmp/b.npz

The scenes cover direct echoes, schools, swimbladders, a moving and a rolling platform, moving
seas (swell, wind sea) with multipath and reverberation, Doppler, arrivals, noise and the ADC.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
#: (scene, pings, record arrivals)
CASES = [("default", 3, None), ("two_targets", 3, None), ("school_along_fan", 3, None),
         ("swell_ghost", 3, None), ("rolling_swell", 3, None), ("fish_passing", 3, None),
         ("multipath_surface", 3, True), ("pelagic_wind_sea", 2, True), ("hard_survey", 1, None)]


def dump(out: str) -> None:
    import acoustics
    arrays = {}
    for name, n, arrivals in CASES:
        t0 = time.perf_counter()
        tree = acoustics.simulate(str(ROOT / "scenes" / f"{name}.yaml"), pings=n, arrivals=arrivals)
        for node in tree.subtree:
            if "Provenance" in node.path:
                continue
            for var, da in node.to_dataset(inherit=False).data_vars.items():
                if da.dtype.kind in "fiucb":
                    arrays[f"{name}:{node.path}:{var}"] = da.values
                elif da.dtype.kind in "OU":
                    arrays[f"{name}:{node.path}:{var}"] = np.asarray(da.values, str)
        print(f"{name}: {n} ping(s), {time.perf_counter() - t0:.1f} s", flush=True)
    np.savez(out, **arrays)


def compare(a_path: str, b_path: str) -> int:
    a, b = np.load(a_path), np.load(b_path)
    missing = set(a.files) ^ set(b.files)
    differ = [k for k in sorted(set(a.files) & set(b.files))
              if a[k].shape != b[k].shape or a[k].tobytes() != b[k].tobytes()]
    print(f"{len(a.files)} arrays of {len({k.split(':')[0] for k in a.files})} scenes compared: "
          + ("all bit-identical" if not (missing or differ) else
             f"{len(differ)} differ {differ[:10]}, {len(missing)} in one dump only {sorted(missing)[:10]}"))
    return 1 if missing or differ else 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("dump").add_argument("out")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args()
    raise SystemExit(dump(args.out) if args.cmd == "dump" else compare(args.a, args.b))
