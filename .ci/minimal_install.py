"""CI step: abacus installed without extras, in a fresh virtual environment, does the main job,
and each command that needs a missing extra says which in one line (exit status 2).

    python .ci/minimal_install.py          # from the checkout; ≈ 1–2 min with pip's cache warm

The checkout's files (tracked and not ignored, as they are in the work tree) are copied to a
temporary folder and installed from there with ``pip install .`` (no extras), so the checkout
gets no build/ or *.egg-info. Then, in that copy:

- ``abacus run scenes/default.yaml -o OUT --pings 3`` succeeds and writes the numbers and the
  figures (matplotlib and netCDF4 are required dependencies);
- ``abacus view``, ``abacus simulate -o x.zarr``, ``abacus experiment --workers 1`` and
  ``abacus track`` (scores against the truth) each print one line naming their extra, exit 2.

Needs only a package registry (pip's cache helps). Exits non-zero on the first failure.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OPTIONAL = ("pyvista", "vtk", "dask", "distributed", "zarr", "motmetrics")


def fail(message: str) -> None:
    print(f"minimal install: FAILED: {message}", file=sys.stderr)
    sys.exit(1)


def checkout_files() -> list[str]:
    """The checkout's files as git sees them (tracked or untracked, not ignored)."""
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                             cwd=ROOT, capture_output=True, check=True).stdout
        return [f for f in out.decode().split("\0") if f]
    except (OSError, subprocess.CalledProcessError):   # not a git checkout: every file
        return [str(p.relative_to(ROOT)) for p in ROOT.rglob("*") if p.is_file()
                and not {".git", "build", "__pycache__", ".venv"} & set(p.relative_to(ROOT).parts)]


def copy_checkout(dest: Path) -> None:
    for name in checkout_files():
        src = ROOT / name
        if src.is_file():            # a file deleted in the work tree is not copied
            target = dest / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, target)


def run(cmd, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)


def main() -> int:
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="abacus-minimal-") as tmp:
        tmp = Path(tmp)
        src, venv = tmp / "abacus", tmp / "venv"
        copy_checkout(src)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        py = venv / "bin" / "python"
        cli = venv / "bin" / "abacus"
        r = run([py, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "."], cwd=src)
        if r.returncode != 0:
            fail(f"pip install . (exit {r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
        print(f"minimal install: pip install . (no extras) in a fresh venv: "
              f"{time.perf_counter() - t0:.0f} s")
        probe = ("import importlib.util as u; "
                 f"print(' '.join(m for m in {OPTIONAL!r} if u.find_spec(m)))")
        present = run([py, "-c", probe], cwd=tmp).stdout.split()
        if present:
            fail(f"the minimal install pulled in optional packages: {', '.join(present)}")
        env = dict(os.environ, ABACUS_CACHE_DIR=str(tmp / "cache"), MPLBACKEND="Agg")
        env.pop("PYTHONPATH", None)

        # the main job, figures included
        out = tmp / "out"
        t1 = time.perf_counter()
        r = run([cli, "run", "scenes/default.yaml", "-o", out, "--pings", "3"], cwd=src, env=env)
        if r.returncode != 0:
            fail(f"abacus run (exit {r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
        for name in ("run.nc", "counts.json", "detections.csv", "images", "counts", "beams"):
            if not (out / name).exists():
                fail(f"abacus run wrote no {name} in {sorted(p.name for p in out.iterdir())}")
        print(f"minimal install: abacus run scenes/default.yaml -o OUT --pings 3: exit 0 in "
              f"{time.perf_counter() - t1:.0f} s, wrote {', '.join(sorted(p.name for p in out.iterdir()))}")
        for line in r.stdout.splitlines():
            if line.startswith(("count", "outputs in")):
                print(f"    {line}")

        # each extra, named in one line
        r = run([cli, "simulate", "two_targets", "-o", "two.nc", "--pings", "3"], cwd=tmp, env=env)
        if r.returncode != 0:
            fail(f"abacus simulate (exit {r.returncode}): {r.stderr[-2000:]}")
        checks = [
            (["view", "scenes/default.yaml", "-o", tmp / "x.png"], src, "view", tmp / "x.png"),
            (["simulate", "two_targets", "-o", "two.zarr"], tmp, "zarr", tmp / "two.zarr"),
            (["experiment", "two_targets", "-o", "exp", "--pings", "2", "--workers", "1"], tmp,
             "experiment", tmp / "exp"),
            (["track", "two.nc", "-o", "tracks.nc"], tmp, "metrics", tmp / "tracks.nc"),
        ]
        for args, cwd, extra, output in checks:
            r = run([cli, *args], cwd=cwd, env=env)
            lines = r.stderr.strip().splitlines()
            want = f"needs the extra '{extra}': pip install \"abacus[{extra}]\""
            shown = "abacus " + " ".join(str(a) for a in args).replace(str(tmp), "TMP")
            if r.returncode != 2 or len(lines) != 1 or not lines[0].startswith("error: ") \
                    or not lines[0].endswith(want):
                fail(f"{shown}: expected exit 2 and one line ending {want!r}, got exit "
                     f"{r.returncode}:\n{r.stderr[-3000:]}")
            if output.exists():
                fail(f"{shown}: wrote {output.name} although it failed")
            print(f"minimal install: {shown}: exit 2, {lines[0]}")
    print(f"minimal install: ok ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
