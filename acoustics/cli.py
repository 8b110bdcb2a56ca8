"""The ``abacus`` command line. The only layer (with the tests) that joins acoustics and
processing as peers; user errors end in one message and exit status 2, never a traceback."""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from processing.config import ConfigError
from processing.dataset import DatasetError
from processing.noise import NoiseEstimateError

__all__ = ["main"]

DEFAULT_SCENE = Path(__file__).resolve().parent.parent / "scenes" / "default.yaml"


class UsageError(Exception):
    """A bad option or argument: printed as one line, exit status 2."""


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"warning: {message}", file=sys.stderr)


def _load(path):
    from .scene import load_scene
    return load_scene(path)


# ------------------------------------------------------------------- commands
def cmd_scene(args) -> int:
    from .scene import json_schema_text
    if args.action == "schema":
        sys.stdout.write(json_schema_text())
        return 0
    if args.file is None:
        raise UsageError(f"abacus scene {args.action}: give a scene FILE")
    scene = _load(args.file)
    if args.action == "check":
        meshes = ""
        if scene.boundaries or scene.targets.meshes:
            # build every mesh now, so a bad mesh file fails here and not mid-run
            from .sonar import build_sonar
            from .meshes import scene_meshes
            built = scene_meshes(scene, build_sonar(scene).pose)
            meshes = f", {len(built)} mesh(es), {sum(len(m.mesh.faces) for m in built)} faces"
        print(f"{args.file}: ok — scene '{scene.name}', {scene.pings.count} ping(s){meshes}, "
              f"sha256 {scene.sha256()[:12]}")
    else:
        sys.stdout.write(scene.resolved_text())
    return 0


def _beams(scene, outdir: Path | None, as_json: bool) -> dict:
    from .beam_table import beam_arrays, beam_cuts, beam_table, format_beam_table
    from .medium import Medium
    medium = Medium.from_spec(scene.medium)
    f0 = scene.signal.center_frequency_hz
    geometry = (scene.sonar.preset_geometry.model_dump()
                if scene.sonar.preset == "abacus" and scene.sonar.variant == "abacus" else None)
    table = beam_table(medium=medium, frequency_hz=f0, geometry=geometry)
    if as_json:
        print(json.dumps(table, indent=2))
    else:
        print(f"Beam patterns at f0 = {f0 / 1e3:g} kHz, c = {medium.sound_speed_m_s:g} m/s "
              f"(λ = {medium.sound_speed_m_s / f0 * 1e3:.4g} mm)")
        print(format_beam_table(table))
    if outdir is not None:
        from .plot_beams import plot_beam_figures
        cuts = beam_cuts(beam_arrays(geometry), medium=medium, frequency_hz=f0)
        paths = plot_beam_figures(cuts, outdir)
        if not as_json:
            for p in paths:
                print(f"wrote {p}")
    return table


def cmd_beams(args) -> int:
    scene = _load(args.scene or DEFAULT_SCENE)
    _beams(scene, Path(args.plots) if args.plots else None, args.json)
    return 0


class _Progress:
    """A one-line progress bar on stderr, only when stderr is a terminal."""

    def __init__(self, label: str):
        self.label = label
        self.on = sys.stderr.isatty()

    def __call__(self, done: int, total: int):
        if not self.on:
            return
        width = 30
        fill = int(width * done / max(total, 1))
        end = "\n" if done >= total else ""
        print(f"\r{self.label} [{'#' * fill}{'.' * (width - fill)}] {done}/{total}", end=end,
              file=sys.stderr, flush=True)


def _ping_list(scene, n: int | None):
    if n is None:
        return None
    if n < 1:
        raise UsageError(f"--pings must be >= 1, got {n}")
    return range(scene.pings.first, scene.pings.first + n)


def cmd_simulate(args) -> int:
    from processing.dataset import write_tree
    from .simulate import simulate
    scene = _load(args.scene)
    out = Path(args.output)
    fmt = args.format or ("zarr" if out.suffix == ".zarr" else "netcdf")
    if args.seed is not None and args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}")
    tree = simulate(scene, pings=_ping_list(scene, args.pings), seed=args.seed,
                    progress=_Progress("simulate"))
    write_tree(tree, out, fmt=fmt)
    prov = tree["Provenance"].ds
    n_p = tree["Simulation/Element_group1"].sizes["ping_time"]
    print(f"wrote {out} ({fmt}): {n_p} ping(s); stages: "
          + ", ".join(f"{s} {t:.2f} s" for s, t in zip(prov["stage"].values, prov["stage_seconds"].values)))
    clipped = tree["Simulation/Element_group1"].ds.get("adc_clipped_samples")
    if clipped is not None and int(clipped.sum()):
        print(f"warning: the ADC clipped {int(clipped.sum())} samples", file=sys.stderr)
    return 0


def cmd_image(args) -> int:
    import processing
    from processing.dataset import open_tree, write_tree
    tree = open_tree(args.input)
    out_tree = processing.image(tree, args.settings)
    if args.output:
        write_tree(out_tree, Path(args.output))
        print(f"wrote {args.output}")
    if args.plots:
        from processing.plots import image_figures
        for p in image_figures(processing.images_of(out_tree), Path(args.plots), ping=args.ping):
            print(f"wrote {p}")
    if not args.output and not args.plots:
        raise UsageError("abacus image: give -o OUT and/or --plots DIR")
    return 0


def cmd_count(args) -> int:
    import processing
    from processing.dataset import open_tree, write_tree
    tree = processing.count(open_tree(args.input), args.settings)
    result = processing.count_summary(tree)
    if args.output:
        write_tree(tree, Path(args.output))
    if args.csv:
        processing.write_csv(tree, args.csv)
    if args.plots:
        from processing.plots import count_figures
        n = tree["Processing/Counts"].sizes["ping_time"]
        count_figures(tree, Path(args.plots), pings=range(min(n, 5)))
    if args.json:
        print(json.dumps(result))
    else:
        print(processing.format_counts(result))
        for what, where in (("dataset", args.output), ("detections CSV", args.csv), ("plots", args.plots)):
            if where:
                print(f"wrote {what}: {where}")
    return 0


def cmd_view(args) -> int:
    from .view import render_scene
    scene = _load(args.scene)
    out = render_scene(scene, args.output, ping=args.ping, interactive=args.interactive)
    if out:
        print(f"wrote {out}")
    return 0


def cmd_run(args) -> int:
    """The main job: simulate, image, detect, locate, count; dataset and plots in DIR."""
    import processing
    from processing.dataset import write_tree
    from .simulate import simulate
    scene = _load(args.scene)
    outdir = Path(args.output or Path("runs") / scene.name)
    outdir.mkdir(parents=True, exist_ok=True)
    print(f"scene '{scene.name}' ({args.scene}): {scene.pings.count} ping(s), "
          f"sha256 {scene.sha256()[:12]}")
    (outdir / "scene.resolved.yaml").write_text(scene.resolved_text())
    _beams(scene, outdir / "beams", False)
    tree = simulate(scene, pings=_ping_list(scene, args.pings), progress=_Progress("simulate"))
    tree = processing.count(tree)
    result = processing.count_summary(tree)
    write_tree(tree, outdir / "run.nc")
    processing.write_csv(tree, outdir / "detections.csv")
    (outdir / "counts.json").write_text(json.dumps(result, indent=1))
    from processing.plots import count_figures, image_figures
    image_figures(processing.images_of(tree), outdir / "images")
    n = tree["Processing/Counts"].sizes["ping_time"]
    count_figures(tree, outdir / "counts", pings=range(min(n, 3)))
    print()
    print(processing.format_counts(result))
    print(f"\noutputs in {outdir}/: run.nc (dataset), detections.csv, counts.json, beams/, images/, counts/")
    return 0


def cmd_experiment(args) -> int:
    """Monte Carlo over pings (and a sweep), in parallel with Dask; dataset and report in DIR."""
    from .experiment import ExperimentError, parse_sweep, run_experiment
    scene = _load(args.scene)
    try:
        sweep = parse_sweep(args.sweep) if args.sweep else None
        out = Path(args.output)
        fmt = args.format or "netcdf"
        t0 = time.perf_counter()
        path = run_experiment(scene, out, pings=_ping_list(scene, args.pings), sweep=sweep,
                              workers=args.workers, scheduler=args.scheduler, fmt=fmt,
                              restart=args.restart, progress=_Progress("experiment"))
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
    print(f"outputs in {out}/: {path.name}, report.html, figures/, parts/ (kept for resuming)")
    return 0


# --------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="abacus", description=__doc__.split(".")[0] + ".")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    r = sub.add_parser("run", help="the main job: simulate, image, detect, locate, count")
    r.add_argument("scene", help="scene file (YAML)")
    r.add_argument("-o", "--output", help="output folder (default runs/<scene name>)")
    r.add_argument("--pings", type=int, help="number of pings (default: the scene's)")
    r.set_defaults(func=cmd_run)

    s = sub.add_parser("scene", help="check a scene file, show it resolved, or print the schema")
    s.add_argument("action", choices=["check", "show", "schema"])
    s.add_argument("file", nargs="?", help="scene file (YAML)")
    s.set_defaults(func=cmd_scene)

    b = sub.add_parser("beams", help="beamwidth and sidelobe table, beam-pattern plots")
    b.add_argument("scene", nargs="?", help="scene file (default scenes/default.yaml)")
    b.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    b.add_argument("--plots", metavar="DIR", help="write PNG plots into DIR")
    b.set_defaults(func=cmd_beams)

    m = sub.add_parser("simulate", help="simulate a scene's per-element echoes into a dataset")
    m.add_argument("scene", help="scene file (YAML)")
    m.add_argument("-o", "--output", required=True, help="output file (.nc) or folder (.zarr)")
    m.add_argument("--pings", type=int, help="number of pings (default: the scene's)")
    m.add_argument("--seed", type=int, help="seed (default: the scene's)")
    m.add_argument("--format", choices=["netcdf", "zarr"], help="default from the suffix")
    m.set_defaults(func=cmd_simulate)

    i = sub.add_parser("image", help="pulse compression, beamforming, interferometry of a dataset")
    i.add_argument("input", help="dataset (.nc or .zarr)")
    i.add_argument("-o", "--output", help="output dataset with /Processing added")
    i.add_argument("--plots", metavar="DIR", help="write PNG figures into DIR")
    i.add_argument("--settings", metavar="YAML", help="processing settings (default: the scene's)")
    i.add_argument("--ping", type=int, default=0, help="ping to plot (index in the file)")
    i.set_defaults(func=cmd_image)

    c = sub.add_parser("count", help="detect, locate and count targets in a dataset")
    c.add_argument("input", help="dataset (.nc or .zarr); imaged first if needed")
    c.add_argument("-o", "--output", help="output dataset with detections and counts")
    c.add_argument("--settings", metavar="YAML", help="processing settings (default: the scene's)")
    c.add_argument("--json", action="store_true", help="print one JSON object: per-ping counts and summary")
    c.add_argument("--plots", metavar="DIR", help="detections over fan-beam images, counts vs ping")
    c.add_argument("--csv", metavar="FILE", help="write the detections table as CSV")
    c.set_defaults(func=cmd_count)

    e = sub.add_parser("experiment", help="Monte Carlo over pings and a sweep, in parallel (Dask); "
                       "dataset and report")
    e.add_argument("scene", help="scene file (YAML)")
    e.add_argument("-o", "--output", required=True, help="output folder (rerun to resume)")
    e.add_argument("--pings", type=int, help="number of pings (default: the scene's)")
    e.add_argument("--sweep", metavar="KEY=SPEC",
                   help="KEY=START:STOP:STEP or KEY=V1,V2,...; KEY a dotted scene path or 'threshold'")
    e.add_argument("--workers", type=int, help="local Dask worker processes (default: every core; "
                   "0: in this process)")
    e.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, e.g. tcp://host:8786")
    e.add_argument("--format", choices=["netcdf", "zarr"], help="results format (default netcdf)")
    e.add_argument("--restart", action="store_true", help="discard finished pings of an earlier run in DIR")
    e.set_defaults(func=cmd_experiment)

    v = sub.add_parser("view", help="3-D view of a scene (meshes, sonar, beam, targets)")
    v.add_argument("scene", help="scene file (YAML)")
    v.add_argument("-o", "--output", help="PNG file to write")
    v.add_argument("--ping", type=int, default=0, help="ping whose targets to draw")
    v.add_argument("--interactive", action="store_true", help="open a window (needs a display)")
    v.set_defaults(func=cmd_view)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    warnings.showwarning = _show_warning
    try:
        return int(args.func(args) or 0)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (DatasetError, NoiseEstimateError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
