"""Shared machinery of the benchmark scripts: a registry of sections, timing, markdown tables,
and an atomic writer that can regenerate one section and keep the others."""
from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import re
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def best_time(fn, *, repeat=3, number=1):
    """Best wall time (s) of ``number`` calls over ``repeat`` trials (noisy shared machine)."""
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


def machine() -> str:
    return (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
            f"Python {platform.python_version()}, numpy {np.__version__}")


class Report:
    """Named sections, each produced by a function returning markdown."""

    def __init__(self, title: str, intro: str, output: Path):
        self.title, self.intro, self.output = title, intro, output
        self.sections: dict = {}

    def section(self, fn):
        self.sections[fn.__name__] = fn
        return fn

    def main(self, argv=None):
        ap = argparse.ArgumentParser(description=self.title)
        ap.add_argument("--only", nargs="*", choices=sorted(self.sections),
                        help="regenerate only these sections (the others are kept)")
        ap.add_argument("-o", "--output", default=str(self.output))
        args = ap.parse_args(argv)
        out = Path(args.output)
        done: dict[str, str] = {}
        if args.only and out.exists():
            text = out.read_text()
            for name in self.sections:
                marker = f"<!-- section:{name} -->"
                if marker in text:
                    done[name] = text.split(marker)[1].split("<!-- /section -->")[0].strip()
        for name in args.only or self.sections:
            t0 = time.perf_counter()
            print(f"running {name} ...", flush=True)
            done[name] = self.sections[name]().strip()
            print(f"  {name}: {time.perf_counter() - t0:.1f} s", flush=True)
        body = (f"# {self.title}\n\n{self.intro.strip()}\n\nMachine: {machine()}. Generated "
                f"{_dt.date.today().isoformat()}. Times are best-of-N wall clock on a shared "
                f"machine: compare ratios within a table, not absolute numbers across runs.\n")
        for name in self.sections:
            if name in done:
                body += f"\n<!-- section:{name} -->\n{done[name]}\n<!-- /section -->\n"
        # sections another script writes into the same file (benchmarks/elevation_precision.py)
        # are kept as they are, after this script's own
        if out.exists():
            for m in re.finditer(r"<!-- section:(\w+) -->\n.*?<!-- /section -->", out.read_text(), re.S):
                if m.group(1) not in self.sections:
                    body += f"\n{m.group(0)}\n"
        tmp = out.with_suffix(out.suffix + ".tmp")
        tmp.write_text(body)
        tmp.replace(out)
        print(f"wrote {out}")
