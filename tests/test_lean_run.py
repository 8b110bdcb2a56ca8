"""What keeps a run lean: no needless imports, a figure helper that draws what this process
would, memory that does not hold the samples twice. Speed itself is measured in
benchmarks/speed.py ("end to end"), not here."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import psutil
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _python(code: str, cwd) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    out = subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_writing_restores_the_netcdf_chunk_cache(tmp_path):
    import netCDF4

    import acoustics
    import processing
    before = netCDF4.get_chunk_cache()
    tree = acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(1))
    processing.write_tree(tree, tmp_path / "a.nc")
    assert netCDF4.get_chunk_cache() == before
    back = processing.open_tree(tmp_path / "a.nc")
    g = "Sonar/Beam_group1"
    np.testing.assert_array_equal(back[g]["backscatter_r"].values, tree[g]["backscatter_r"].values)


def test_the_figure_helper_imports_only_what_it_draws_with(tmp_path):
    """The helper (matplotlib, abacus.figures.plots, a warm-up draw, a fan-beam resampling) loads
    none of the run's heavy modules: scipy alone cost it ≈ 0.3 s of its start."""
    got = _python(
        "import json, sys, numpy as np\n"
        "import matplotlib; matplotlib.use('Agg')\n"
        "import abacus.figures.plots as p\n"
        "from abacus.cli.figure_worker import _warm_up; _warm_up()\n"
        "p.fan_beam(np.ones((50, 8)), np.linspace(1, 5, 50), np.linspace(-0.1, 0.1, 8))\n"
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules} & "
        "{'scipy', 'xarray', 'pandas', 'numba', 'pydantic', 'netCDF4', 'h5py'})))",
        tmp_path)
    assert got == []


def test_the_figure_helper_draws_what_this_process_draws(tmp_path):
    """Same pixels from the helper process as from matplotlib here."""
    from PIL import Image

    import acoustics
    import processing
    from abacus.cli.figure_worker import FigureWorker
    from abacus.figures.plots import count_figure_data, draw_counts_figure, draw_detection_figure
    tree = processing.count(acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(2)))
    data = count_figure_data(tree, pings=[1])
    here, there = tmp_path / "here", tmp_path / "there"
    draw_detection_figure(data["detections"][0], here)
    draw_counts_figure(data["counts"], here)
    with FigureWorker() as helper:
        tickets = [helper.submit("draw_detection_figure", data["detections"][0], there),
                   helper.submit("draw_counts_figure", data["counts"], there)]
        paths = [p for t in tickets for p in helper.result(t)]
    assert sorted(Path(p).name for p in paths) == ["counts.png", "detections_ping1.png"]
    for name in ("counts.png", "detections_ping1.png"):
        a, b = (np.asarray(Image.open(d / name)) for d in (here, there))
        assert a.shape == b.shape and np.array_equal(a, b), name


def test_the_run_figures_put_titles_where_matplotlib_would(tmp_path):
    """Titles fixed at the top of their axes (no measuring of tick labels per draw) give the
    same pixels as matplotlib's own placement for every figure a run draws."""
    from PIL import Image

    import acoustics
    import processing
    from abacus.figures import plots
    from processing.records import figure_images
    tree = processing.count(acoustics.simulate(acoustics.load_scene("default"), pings=range(1)))
    images = plots.image_figure_data(figure_images(tree, [0]))
    counts = plots.count_figure_data(tree, pings=[0])
    for draw in (plots.draw_image_figures, plots.draw_detection_figures, plots.draw_counts_figure):
        data = {plots.draw_image_figures: images, plots.draw_detection_figures: counts["detections"],
                plots.draw_counts_figure: counts["counts"]}[draw]
        fast, auto = draw(data, tmp_path / "fast"), draw.__wrapped__(data, tmp_path / "auto")
        for a, b in zip(*(p if isinstance(p, list) else [p] for p in (fast, auto))):
            assert np.array_equal(np.asarray(Image.open(a)), np.asarray(Image.open(b))), Path(a).name


def test_queued_figures_are_drawn_by_forked_copies_that_die_with_the_helper(tmp_path):
    """Figures sent together are drawn side by side by copies of the helper, one per spare
    core (none on one core), with the same pixels as here; killing the helper ends its copies."""
    import threading
    import time

    from PIL import Image

    import acoustics
    import processing
    from abacus.cli.figure_worker import FigureWorker
    from abacus.figures.plots import count_figure_data, draw_detection_figure
    tree = processing.count(acoustics.simulate(acoustics.load_scene("default"), pings=range(3)))
    data = count_figure_data(tree, pings=range(3))["detections"]
    seen, stop = set(), threading.Event()

    def watch(pid):
        while not stop.is_set():
            try:
                seen.update(c.pid for c in psutil.Process(pid).children())
            except psutil.Error:
                pass
            time.sleep(0.01)

    with FigureWorker() as helper:
        watcher = threading.Thread(target=watch, args=(helper._proc.pid,), daemon=True)
        watcher.start()
        # sent together, so that the helper finds them all waiting (one by one, the second
        # could still be on its way when the helper takes the first)
        tickets = helper.submit_together([("draw_detection_figure", d, tmp_path / "there") for d in data])
        paths = [p for t in tickets for p in helper.result(t)]
        stop.set()
        watcher.join()
    spare = len(os.sched_getaffinity(0)) >= 2
    assert bool(seen) == spare, f"forked copies {sorted(seen)} with spare cores: {spare}"
    assert sorted(Path(p).name for p in paths) == [f"detections_ping{d['ping_index']}.png" for d in data]
    for d, path in zip(data, paths):
        here = draw_detection_figure(d, tmp_path / "here")
        assert np.array_equal(np.asarray(Image.open(here)), np.asarray(Image.open(path)))

    if not spare:
        return
    helper = FigureWorker()
    helper.submit_together([("draw_detection_figure", d, tmp_path / "killed") for d in data * 3])
    deadline, copies = time.monotonic() + 120, []
    while not copies and time.monotonic() < deadline:
        copies = psutil.Process(helper._proc.pid).children()
        time.sleep(0.01)
    assert copies, "no forked copy began"
    helper.kill()
    gone, alive = psutil.wait_procs(copies, timeout=5)
    assert not [p for p in alive if _running(p)]     # dead, if perhaps not yet reaped


@pytest.mark.parametrize("n, drawers", [(3, 2), (3, 4), (3, 1), (1, 2), (0, 2), (7, 3), (2, 5)])
def test_the_run_splits_its_last_figures_evenly_over_the_drawers(n, drawers):
    """Every figure once, in order, in at most ``drawers`` consecutive shares that differ by at
    most one figure, the larger first (the forked copies take the first shares and start first)."""
    from abacus.cli.run import drawing_shares
    shares = drawing_shares(n, drawers)
    figures = list(range(n))
    assert [i for s in shares for i in figures[s]] == figures
    sizes = [len(figures[s]) for s in shares]
    assert len(shares) <= max(1, drawers) and (n == 0 or min(sizes) >= 1)
    assert max(sizes) - min(sizes) <= 1 and sizes == sorted(sizes, reverse=True)
    assert len(shares) == max(1, min(n, drawers))     # no drawer idle while another has two


def _running(proc) -> bool:
    try:
        return proc.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def test_a_figure_that_fails_is_one_error_and_the_helper_ends(tmp_path):
    from abacus.cli.figure_worker import FigureError, FigureWorker
    helper = FigureWorker()
    with pytest.raises(ValueError, match="unknown figure job"):
        helper.submit("os.system", {}, tmp_path)
    with pytest.raises(ValueError, match="unknown figure job"):    # nothing of the batch is sent
        helper.submit_together([("draw_counts_figure", {}, tmp_path), ("os.system", {}, tmp_path)])
    assert helper.submit_together([]) == []                       # nothing to send, nothing sent
    ticket = helper.submit("draw_counts_figure", {"ping_index": np.arange(3)}, tmp_path)
    with pytest.raises(FigureError, match="draw_counts_figure"):
        helper.result(ticket)
    ok = helper.submit("draw_counts_figure", {"ping_index": np.arange(3), "count_before": np.ones(3),
                                              "count_after": np.ones(3),
                                              "density_per_m3": np.ones(3)}, tmp_path)
    assert Path(helper.result(ok)[0]).is_file()        # a failed job does not end the helper
    proc = helper._proc
    helper.kill()
    assert proc.poll() is not None


def test_a_run_folder_killed_while_drawing_leaves_nothing_a_rerun_does_not_remove(tmp_path):
    """The first ping's figures are drawn into a scratch folder next to the run folder before it
    exists; if the run is killed, the next write of that run folder removes it."""
    from processing.base.atomic import TMP_MARK, scratch, staged
    stale = tmp_path / f".out.images{TMP_MARK}999999-0123abcd"     # a dead process' scratch
    stale.mkdir()
    (stale / "fan_beam.png").write_bytes(b"x")
    with staged(tmp_path / "out") as tmp:
        tmp.mkdir()
    assert not stale.exists() and (tmp_path / "out").is_dir()
    with scratch(tmp_path, "out.images") as folder:
        assert folder.is_dir() and folder.name.startswith(".out.images" + TMP_MARK)
    assert not folder.exists()


def test_the_figure_helper_dies_with_a_killed_run(tmp_path):
    """SIGKILL on the run alone (no handler can run): the kernel ends its helper too, and the
    next write of the run folder removes what they left."""
    import signal
    import time

    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg",
               ABACUS_CACHE_DIR=str(tmp_path / "cache"))
    proc = subprocess.Popen([sys.executable, "-m", "abacus", "run", "default", "-o", "out",
                             "--pings", "400"], cwd=tmp_path, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        helpers = []
        while not helpers and time.monotonic() < deadline and proc.poll() is None:
            helpers = [p for p in psutil.Process(proc.pid).children()
                       if "figure_worker" in " ".join(p.cmdline())]
            time.sleep(0.05)
        assert helpers, "the run started no figure helper"
        scratch = []
        while not scratch and time.monotonic() < deadline and proc.poll() is None:
            scratch = [p for p in tmp_path.iterdir() if p.name.startswith(".out.images.tmp-")]
            time.sleep(0.05)
        assert scratch, "the first ping's figures were not begun while the run went on"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        gone, alive = psutil.wait_procs(helpers, timeout=5)
        assert not alive
    finally:
        if proc.poll() is None:
            proc.kill()
    out = subprocess.run([sys.executable, "-m", "abacus", "run", "default", "-o", "out",
                          "--pings", "1", "--no-plots"], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert not scratch[0].exists()
    assert not [p.name for p in tmp_path.iterdir() if ".tmp-" in p.name]


def test_a_cold_run_has_its_beam_figures_drawn_by_the_helper_and_cached(tmp_path):
    """With an empty geometry cache the helper draws beams/ (the same pixels as drawing here)
    and the run caches them, so the next run copies them."""
    from PIL import Image

    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg",
               ABACUS_CACHE_DIR=str(tmp_path / "cache"))
    run = subprocess.run([sys.executable, "-m", "abacus", "run", "two_targets", "-o", "out",
                          "--pings", "1"], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr
    assert [p.name for p in (tmp_path / "cache").glob("beam_figures-*")]
    here = subprocess.run([sys.executable, "-c", "import acoustics; from abacus.cli.beams import "
                           "beam_figures; beam_figures(acoustics.load_scene('two_targets'), 'here')"],
                          cwd=tmp_path, env=dict(env, ABACUS_CACHE_DIR="off"), capture_output=True,
                          text=True, timeout=600)
    assert here.returncode == 0, here.stderr
    names = sorted(p.name for p in (tmp_path / "here").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "out" / "beams").iterdir()) and len(names) == 3
    for name in names:
        a, b = (np.asarray(Image.open(d / name)) for d in (tmp_path / "here", tmp_path / "out" / "beams"))
        assert a.shape == b.shape and np.array_equal(a, b), name


def test_a_command_line_sets_quiet_threads_before_numpy_loads_and_keeps_the_users(tmp_path):
    """`abacus ...` (main() with the process' own command line) sets OMP_WAIT_POLICY=PASSIVE
    and OPENBLAS_NUM_THREADS=1 before numpy (and OpenBLAS, which reads it once) is imported,
    unless the user set them; main(argv) inside another program leaves the environment alone."""
    code = ("import json, os, sys\n"
            "import abacus.cli.app as app\n"
            "seen = {}\n"
            "def command(argv):\n"
            "    seen.update(numpy='numpy' in sys.modules, omp=os.environ.get('OMP_WAIT_POLICY'),\n"
            "                blas=os.environ.get('OPENBLAS_NUM_THREADS'))\n"
            "    return 0\n"
            "app._command = command\n"
            "app._exit_now = lambda code, *a: None\n"
            "app.main(None if sys.argv[1] == 'cli' else ['--version'])\n"
            "print(json.dumps(seen))")
    base = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "OPENBLAS_NUM_THREADS")}

    def seen(mode, **env):
        out = subprocess.run([sys.executable, "-c", code, mode], env=dict(base, PYTHONPATH=str(ROOT), **env),
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr[-2000:]
        return json.loads(out.stdout.strip().splitlines()[-1])
    assert seen("cli") == {"numpy": False, "omp": "PASSIVE", "blas": "1"}
    assert seen("cli", OMP_WAIT_POLICY="ACTIVE", OPENBLAS_NUM_THREADS="4") == \
        {"numpy": False, "omp": "ACTIVE", "blas": "4"}
    assert seen("embedded") == {"numpy": False, "omp": None, "blas": None}


@pytest.mark.parametrize("chosen, spin", [(None, "0"), ("ACTIVE", None)])
def test_the_kernels_threads_wait_asleep_unless_the_user_chose(tmp_path, chosen, spin):
    """A command's OpenMP threads (numba's omp layer, GNU libgomp) do not spin between parallel
    loops (GOMP_SPINCOUNT 0, as libgomp reports it when it starts), where they would take the
    cores from the figure helper; a user's own OMP_WAIT_POLICY is left as it is."""
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    env.update(PYTHONPATH=str(ROOT), MPLBACKEND="Agg", NUMBA_THREADING_LAYER="omp",
               OMP_DISPLAY_ENV="VERBOSE", ABACUS_CACHE_DIR=str(tmp_path / "cache"))
    probe = subprocess.run([sys.executable, "-c", "import numba, numpy as np\n"
                            "f = numba.njit(parallel=True)(lambda x: x.sum())\nf(np.ones(4))"],
                           env=env, capture_output=True, text=True, timeout=300)
    if probe.returncode != 0:
        # numba's omp layer links the system's libgomp; without it there are no OpenMP threads
        # to spin (numba uses its workqueue layer), and nothing to test
        pytest.skip("numba's OpenMP threading layer cannot load here (no libgomp)")
    if chosen:
        env["OMP_WAIT_POLICY"] = chosen
    run = subprocess.run([sys.executable, "-m", "abacus", "simulate", "two_targets", "--pings", "1",
                          "-o", str(tmp_path / "s.nc")], env=env, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    shown = dict(line.strip().split(" = ", 1) for line in run.stderr.splitlines()
                 if line.strip().startswith(("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")))
    assert "GOMP_SPINCOUNT" in shown, "libgomp did not start: " + run.stderr[-500:]
    if spin is not None:
        assert shown["GOMP_SPINCOUNT"] == f"'{spin}'"
    else:      # ACTIVE: libgomp spins far longer than its default 300 000 turns
        assert int(shown["GOMP_SPINCOUNT"].strip("'")) > 300_000
        assert shown["OMP_WAIT_POLICY"] == "'ACTIVE'"
