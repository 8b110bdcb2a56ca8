"""What every command shares: the usage error, scene loading, ping lists, a progress bar."""
from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["UsageError", "load", "ping_list", "Progress", "default_scene_path", "check_output",
           "check_outputs", "add_output_options", "check_scene_resources", "prefetch", "tree_bytes",
           "check_room", "save_tree"]


#: drawing the figures of ``abacus run`` (matplotlib canvases, fonts; measured ≈ 150 MB)
FIGURES_BYTES = 200e6


class UsageError(Exception):
    """A bad option or argument: printed as one line, exit status 2."""


def default_scene_path() -> Path:
    """The built-in default scene (shipped with the package)."""
    from acoustics.scene.builtin import builtin_scene
    return builtin_scene("default")


def load(path):
    """Load a run file (a scene file with its processing block), or a built-in scene by name
    (``default``, ``two_targets``, ...)."""
    from abacus.runfile import load_run
    return load_run(path)


def prefetch(*modules: str):
    """Import ``modules`` on a background thread, for a later stage: the compiled kernels and
    FFTs of the stage before release the interpreter, so the import runs in their shadow
    instead of on the critical path. A module that fails to import here is left for the stage
    itself to import, and to report."""
    import threading

    def load_all():
        import importlib
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:   # the stage that needs it will say why
                pass

    threading.Thread(target=load_all, name="abacus-prefetch", daemon=True).start()


class Progress:
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


def ping_list(scene, n: int | None):
    """Pings first .. first + n − 1 of the scene, or None (the scene's own) when n is None."""
    if n is None:
        return None
    if n < 1:
        raise UsageError(f"--pings must be >= 1, got {n}")
    if n > scene.pings.count:
        # pings the scene's checks have not seen (the sea and the platform at every ping):
        # the scene with that many pings must pass them too (a count beyond the schema's own
        # bound is left to the resource estimate, which names what fits)
        from acoustics.scene import SceneError
        try:
            scene.with_updates({"pings.count": n}, what=f"--pings {n}")
        except SceneError as exc:
            if not all(p.get("key") == "pings.count" for p in (exc.problems or [{}])):
                raise
    return range(scene.pings.first, scene.pings.first + n)


def add_output_options(parser, *, overwrite: bool = True, memory: bool = True):
    """``--overwrite`` and ``--max-memory GB``, shared by the commands that write and allocate."""
    if overwrite:
        parser.add_argument("--overwrite", action="store_true",
                            help="replace an existing output (default: refuse)")
    if memory:
        parser.add_argument("--max-memory", type=float, metavar="GB",
                            help="memory this command may use (default: $ABACUS_MAX_MEMORY_GB, else "
                                 "half the machine's memory); larger runs are refused up front")


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name the same file or folder (links and hard links followed)."""
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    try:
        return a.resolve() == b.resolve()
    except (OSError, RuntimeError):
        return False


def _inside(a: Path, folder: Path) -> bool:
    """Whether ``a`` lies inside ``folder`` (links followed)."""
    try:
        return a.resolve().is_relative_to(folder.resolve()) and a.resolve() != folder.resolve()
    except (OSError, RuntimeError):
        return False


def check_output(path, *, overwrite: bool, option: str = "-o", folder: bool = False,
                 inputs=()) -> Path:
    """The output path of a command, checked before any work: its folder exists, it is not one
    of the command's ``inputs`` (nor a folder holding one) — refused even with ``--overwrite``,
    which replaces outputs, never inputs —, and it is replaced only with ``--overwrite``.

    Raises
    ------
    UsageError
    """
    p = Path(path)
    if str(path).strip() == "":
        raise UsageError(f"{option}: give a file name")
    for given in inputs:
        if given is None or str(given).strip() == "":
            continue
        src = Path(given)
        if _same_file(p, src):
            raise UsageError(f"{option} {p}: is the input {given}; write to another name (an input is "
                             f"never replaced, even with --overwrite)")
        if (p.is_dir() or folder or p.suffix == ".zarr") and _inside(src, p):
            raise UsageError(f"{option} {p}: holds the input {given}; write to another folder (an input is "
                             f"never replaced, even with --overwrite)")
    parent = p.parent
    if not parent.exists():
        raise UsageError(f"{option} {p}: the folder {parent} does not exist (create it first)")
    if not parent.is_dir():
        raise UsageError(f"{option} {p}: {parent} is not a folder")
    if p.exists() or p.is_symlink():
        if not overwrite:
            raise UsageError(f"{option} {p}: exists; choose another name, or --overwrite to replace it")
        if folder and p.exists() and not p.is_dir():
            raise UsageError(f"{option} {p}: is a file, expected a folder")
        if not folder and p.is_dir() and p.suffix != ".zarr":
            raise UsageError(f"{option} {p}: is a folder, expected a file")
    if not os.access(parent, os.W_OK):
        raise UsageError(f"{option} {p}: the folder {parent} is not writable")
    return p


def check_outputs(args, options, *, inputs=()) -> list:
    """Every output option of a command checked (:func:`check_output`) and told apart: two
    options naming the same file, or one inside another's folder, are refused.

    Parameters
    ----------
    args : argparse.Namespace
        With ``overwrite``.
    options : list of (option, value, folder)
        ``("-o", args.output, False)``, ``("--plots", args.plots, True)``; a value None is an
        output not asked for.
    inputs : paths
        The command's inputs (its dataset, settings file), never replaced.

    Returns
    -------
    list of Path or None
        One per option, in order.
    """
    out, seen = [], []
    for option, value, folder in options:
        if value is None:
            out.append(None)
            continue
        p = check_output(value, overwrite=args.overwrite, option=option, folder=folder, inputs=inputs)
        for other, q, q_folder in seen:
            if _same_file(p, q) or (q_folder and _inside(p, q)) or (folder and _inside(q, p)):
                raise UsageError(f"{option} {p}: also given to {other}; give each output its own name")
        seen.append((option, p, folder))
        out.append(p)
    return out


def tree_bytes(tree) -> float:
    """The bytes of a dataset's variables (what a NetCDF4/Zarr file of it holds, uncompressed)."""
    return float(sum(v.nbytes for node in tree.subtree for v in node.ds.variables.values()))


def check_room(n_bytes: float, path, *, what: str):
    """Refuse (exit 3) an output of ≈ ``n_bytes`` that the free space of its folder cannot
    hold (or over ``ABACUS_MAX_OUTPUT_GB``), before anything is written."""
    from processing.base.resources import Estimate, check_resources
    check_resources(Estimate(0.0, float(n_bytes), [], keys="the pings in the input (process it in parts)"),
                    what=what, output=Path(path))


def save_tree(tree, path, *, final=None, fmt=None):
    """Write a dataset (:func:`processing.base.dataset.write_tree`) after checking the free
    space (:func:`check_room`), its library write held from interrupts
    (:func:`processing.base.atomic.interrupts_held`: an interrupt is raised when it ends).

    ``path`` is where to write (a staged temporary), ``final`` the name it will have."""
    from processing.base.atomic import interrupts_held
    from processing.base.dataset import write_tree
    check_room(tree_bytes(tree), final or path, what=str(final or path))
    with interrupts_held():
        if fmt == SONAR_NETCDF2:    # the single targets and gridded Sv where the dataset has them
            from processing.export import write_sonar_netcdf2
            write_sonar_netcdf2(tree, path, command=" ".join(sys.argv))
        else:
            write_tree(tree, path, fmt=fmt)


#: ``--format`` of the commands that write datasets: SONAR-netCDF4 2.0 (1.0, what echopype
#: opens, stays the default: ``netcdf`` or ``zarr``)
SONAR_NETCDF2 = "sonar-netcdf4-2"
DATASET_FORMATS = ("netcdf", "zarr", SONAR_NETCDF2)


def dataset_format(out, fmt) -> str:
    """The format a dataset is written in: ``fmt``, else from the suffix (``.zarr``: Zarr);
    SONAR-netCDF4 2.0 only as a ``.nc`` file (one line otherwise)."""
    fmt = fmt or ("zarr" if Path(out).suffix == ".zarr" else "netcdf")
    if fmt == SONAR_NETCDF2 and Path(out).suffix.lower() != ".nc":
        raise UsageError(f"--format {SONAR_NETCDF2} writes a NetCDF4 file: name the output *.nc, not {Path(out).name}")
    return fmt


def check_scene_resources(scene, args, *, pings=None, images="none", process=True, output=None,
                          figures=False):
    """Refuse a scene whose estimated memory or output exceeds the limits (before any work)."""
    from acoustics.simulation.budget import estimate_scene
    from processing.base.resources import check_resources
    extra = []
    if figures:
        extra.append(("figures", FIGURES_BYTES))
    if process:
        from abacus.runfile import settings_of
        from acoustics.sonar.build import build_sonar
        from processing.chain import chain_memory_terms
        s = scene.sampling
        n = int(scene.pings.count if pings is None else pings)
        extra += chain_memory_terms(
            settings_of(scene), pings=n, channels=int(build_sonar(scene).n_channels),
            samples=int(s.samples), pulse_samples=scene.signal.duration_s * s.rate_hz,
            sample_spacing_m=scene.medium.sound_speed_m_s / (2 * s.rate_hz),
            groups=2 if scene.sonar.mode == "interferometric" else 1, images=images)
    est = estimate_scene(scene, pings=pings, extra_terms=extra)
    check_resources(est, what=f"scene '{scene.name}'", output=output,
                    max_memory_gb=getattr(args, "max_memory", None))
    return est
