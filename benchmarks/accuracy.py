"""Accuracy vs cost of every approximation abacus offers: regenerates docs/accuracy.md.

    python benchmarks/accuracy.py              # every knob
    python benchmarks/accuracy.py --only directivity

Each knob is one function below, registered with ``@knob``; it returns a markdown section
with, for each setting, its error against the reference setting and its time. Times are
wall-clock best-of-N on this machine (shared and noisy: read the ratios, not the absolute
values).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

KNOBS: dict = {}


def knob(fn):
    KNOBS[fn.__name__] = fn
    return fn


def best_time(fn, *, repeat=3, number=1):
    """Best wall time (s) of ``number`` calls, over ``repeat`` trials."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def db(x):
    return 20 * np.log10(max(float(x), 1e-300))


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


# ----------------------------------------------------------------- knobs
@knob
def directivity():
    """Element directivity: far_field vs huygens n x m (reference huygens 32 x 32)."""
    from acoustics.arrays import abacus_transmitter
    from acoustics.directivity import array_response, element_directivity, unit_vector
    from acoustics.medium import Medium

    k = Medium().wavenumber_rad_m(420_375.0)
    tx = abacus_transmitter("abacus")
    rng = np.random.default_rng(0)
    n_pts = 2000
    th = rng.uniform(-np.radians(30), np.radians(30), n_pts)
    ph = rng.uniform(-np.radians(10), np.radians(10), n_pts)
    u = unit_vector(th, ph)
    distances = (0.5, 2.0, 13.0, 40.0)
    settings = [("far_field", None), ("huygens", (1, 1)), ("huygens", (2, 2)),
                ("huygens", (4, 4)), ("huygens", (8, 8)), ("huygens", (16, 16))]
    ref = {r: array_response(tx, u * r, wavenumber_rad_m=k, fidelity="huygens",
                             subdivisions=(32, 32)) for r in distances}
    rows = []
    timing_pts = unit_vector(rng.uniform(-0.5, 0.5, 20_000), rng.uniform(-0.2, 0.2, 20_000)) * 20.0
    for fid, sub in settings:
        errs = []
        for r in distances:
            e = array_response(tx, u * r, wavenumber_rad_m=k, fidelity=fid,
                               subdivisions=sub or (1, 1))
            errs.append(np.abs(e - ref[r]).max())
        t = best_time(lambda: array_response(tx, timing_pts, wavenumber_rad_m=k, fidelity=fid,
                                             subdivisions=sub or (1, 1)), repeat=2)
        label = fid if sub is None else f"huygens {sub[0]}x{sub[1]}"
        rows.append([label] + [f"{db(x):.1f}" for x in errs] + [f"{t / 20_000 * 1e6:.2f}"])
    part1 = table(["setting"] + [f"max error at {r:g} m (dB re on-axis)" for r in distances]
                  + ["time per field point (µs, 16 elements)"], rows)

    # element-level convergence of huygens to far_field with distance (one 0.020 x 0.012 m element)
    el = tx.subset([7])
    th1 = np.radians(np.linspace(-60, 60, 241))
    rows2 = []
    for r in (0.02, 0.05, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0):
        pts = unit_vector(th1, 0.0) * r + el.center_m[0]
        hu = element_directivity(el, pts, wavenumber_rad_m=k, fidelity="huygens", subdivisions=(16, 16))
        ff = element_directivity(el, pts, wavenumber_rad_m=k, fidelity="far_field")
        err = np.abs(hu - ff).max()
        rows2.append([f"{r:g}", f"{err:.3e}", f"{db(err):.1f}", f"{k * 0.02**2 / (8 * r):.3e}"])
    part2 = table(["distance (m)", "max abs(huygens 16x16 − far_field)", "(dB)",
                   "Fresnel phase k w²/(8r) (rad)"], rows2)
    return ("## Element directivity (`effects.directivity`, `effects.huygens_subdivisions`)\n\n"
            "Reference: `huygens` with 32 x 32 sub-pistons per element. The ABACUS transmitter "
            "(16 elements, ganged) evaluated at 2000 random directions within ±30° azimuth and "
            "±10° elevation, at four distances; error is max |E - E_ref| with E = 1 on axis.\n\n"
            + part1 +
            "\n\n`huygens 1x1` equals `far_field` by construction (one sub-piston is the element). "
            "Within the ABACUS observation range (10.5–68 m) `far_field` is within -50 dB of "
            "the converged near-field result at a quarter of the cost of `huygens 2x2`, so it is "
            "the default; `huygens` matters for field points closer than a few metres "
            "(calibration spheres, boundaries near the transducer).\n\n"
            "Convergence of `huygens` to `far_field` with distance, one transmitter element "
            "(0.020 x 0.012 m), azimuth cut ±60°: the error follows the element's Fresnel "
            "phase k w²/(8r), i.e. falls as 1/r.\n\n" + part2)


# ------------------------------------------------------------------ driver
HEADER = """# Accuracy vs cost

Every approximation in abacus has a named setting and a reference setting. This page is
regenerated by `python benchmarks/accuracy.py`; do not edit it by hand.

Machine: {machine}. Generated {date}. Times are best-of-N wall clock on a shared machine:
compare ratios within a table, not absolute numbers across runs.
"""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", choices=sorted(KNOBS), help="run only these knobs")
    ap.add_argument("-o", "--output", default=str(ROOT / "docs" / "accuracy.md"))
    args = ap.parse_args(argv)
    out = Path(args.output)
    sections: dict[str, str] = {}
    if args.only and out.exists():
        # keep the other knobs' sections from the previous run
        text = out.read_text()
        for name in KNOBS:
            marker = f"<!-- knob:{name} -->"
            if marker in text:
                sections[name] = text.split(marker)[1].split("<!-- /knob -->")[0].strip()
    for name in args.only or KNOBS:
        t0 = time.perf_counter()
        print(f"running {name} ...", flush=True)
        sections[name] = KNOBS[name]().strip()
        print(f"  {name}: {time.perf_counter() - t0:.1f} s", flush=True)
    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    body = HEADER.format(machine=machine, date=_dt.date.today().isoformat())
    for name in KNOBS:
        if name in sections:
            body += f"\n<!-- knob:{name} -->\n{sections[name]}\n<!-- /knob -->\n"
    tmp = out.with_suffix(".md.tmp")
    tmp.write_text(body)
    tmp.replace(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
