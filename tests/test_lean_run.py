"""What a run's figures promise whoever draws them (this process or a pool's workers): the same
pixels, one error per failed figure, nothing drawing or left behind once the run ends —
interrupted or killed included. Speed itself is measured in benchmarks/speed.py ("end to end"),
not here."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import psutil
import pytest

ROOT = Path(__file__).resolve().parents[1]


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


@pytest.mark.parametrize("kind", ["Drawing", "PoolDrawing"])
def test_figures_drawn_through_the_interface_are_the_pixels_drawn_here(tmp_path, kind):
    """Same pixels from a job submitted in this process or to the pool as from matplotlib here."""
    from PIL import Image

    import acoustics
    import processing
    from abacus.figures import drawing
    from abacus.figures.plots import count_figure_data, draw_counts_figure, draw_detection_figure
    tree = processing.count(acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(2)))
    data = count_figure_data(tree, pings=[1])
    here, there = tmp_path / "here", tmp_path / "there"
    draw_detection_figure(data["detections"][0], here)
    draw_counts_figure(data["counts"], here)
    with getattr(drawing, kind)() as figures:
        figures.submit(draw_detection_figure, data["detections"][0], there)
        figures.submit(draw_counts_figure, data["counts"], there)
        paths = figures.wait()
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


def _running(proc) -> bool:
    try:
        return proc.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


_COUNTS = {"ping_index": np.arange(3), "count_before": np.ones(3), "count_after": np.ones(3),
           "density_per_m3": np.ones(3)}


@pytest.mark.parametrize("kind", ["Drawing", "PoolDrawing"])
def test_a_figure_that_fails_is_its_own_error_and_the_others_are_drawn(tmp_path, kind):
    """A failed job raises its own error from wait(), whoever drew it; the jobs around it are
    drawn all the same."""
    from abacus.figures import drawing
    from abacus.figures.plots import draw_counts_figure
    with getattr(drawing, kind)() as figures:
        bad = figures.submit(draw_counts_figure, {"ping_index": np.arange(3)}, tmp_path / "bad")
        ok = figures.submit(draw_counts_figure, _COUNTS, tmp_path / "ok")
        with pytest.raises(KeyError, match="count_before"):
            figures.wait()
        with pytest.raises(KeyError, match="count_before"):
            figures.wait([bad])
        assert Path(figures.wait([ok])[0]).is_file()
    assert figures.wait([]) == []


def test_leaving_the_pool_on_an_error_leaves_nothing_drawing(tmp_path):
    """An error (an interrupt) inside the ``with`` block: jobs not begun are dropped, the ones
    being drawn are waited for, and the workers end — nothing writes into the folders after."""
    import time

    from abacus.figures.drawing import PoolDrawing
    from abacus.figures.plots import draw_counts_figure
    folders = [tmp_path / f"f{k}" for k in range(12)]
    workers = []
    with pytest.raises(KeyboardInterrupt):
        with PoolDrawing(workers=2) as figures:
            for folder in folders:
                figures.submit(draw_counts_figure, _COUNTS, folder)
            deadline = time.monotonic() + 120
            while len(workers) < 2 and time.monotonic() < deadline:
                workers = [p for p in psutil.Process().children() if "spawn_main" in " ".join(p.cmdline())]
                time.sleep(0.01)
            raise KeyboardInterrupt
    drawn = sorted(p.name for p in tmp_path.rglob("*"))
    assert len([f for f in folders if f.is_dir()]) < len(folders), "nothing was cancelled"
    time.sleep(1.0)
    assert sorted(p.name for p in tmp_path.rglob("*")) == drawn
    assert workers and not [p for p in workers if _running(p)]
    assert not [p for p in tmp_path.rglob("*") if ".tmp-" in p.name]


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


def _env(tmp_path):
    return dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg",
                ABACUS_CACHE_DIR=str(tmp_path / "cache"))


def _run_until_drawing(tmp_path, env):
    """``abacus run default`` in a process group of its own, once its first figures are being
    drawn (their scratch folder exists); returns the process and that folder."""
    import time
    proc = subprocess.Popen([sys.executable, "-m", "abacus", "run", "default", "-o", "out",
                             "--pings", "300"], cwd=tmp_path, env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline, scratch = time.monotonic() + 240, []
    while not scratch and time.monotonic() < deadline and proc.poll() is None:
        scratch = [p for p in tmp_path.iterdir() if p.name.startswith(".out.images.tmp-")]
        time.sleep(0.02)
    if not scratch:
        proc.kill()
        pytest.fail(f"the first ping's figures were not begun while the run went on: {proc.communicate()}")
    return proc, scratch[0]


def test_ctrl_c_while_drawing_ends_the_run_and_its_figures_cleanly(tmp_path):
    """Ctrl-C reaches the run's whole process group (its figure workers too): the run ends as
    interrupted (130, one line, no traceback from anyone) within 5 s, and leaves no folder, no
    temporary and no process behind."""
    import signal
    import time
    proc, _ = _run_until_drawing(tmp_path, _env(tmp_path))
    family = psutil.Process(proc.pid).children(recursive=True)
    t0 = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert time.monotonic() - t0 < 5.0
    assert proc.returncode == 130 and err.strip() == "interrupted", err
    assert [p.name for p in tmp_path.iterdir() if p.name != "cache"] == []
    gone, alive = psutil.wait_procs(family, timeout=5)
    assert not [p for p in alive if _running(p)]


def test_a_run_killed_while_drawing_leaves_nothing_a_rerun_does_not_remove(tmp_path):
    """SIGKILL on the run alone (no handler can run): its figure workers end too, and the next
    write of the run folder removes what they left."""
    import signal
    env = _env(tmp_path)
    proc, scratch = _run_until_drawing(tmp_path, env)
    workers = psutil.Process(proc.pid).children(recursive=True)
    assert workers, "the run has no figure workers"
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    gone, alive = psutil.wait_procs(workers, timeout=10)
    assert not [p for p in alive if _running(p)]
    out = subprocess.run([sys.executable, "-m", "abacus", "run", "default", "-o", "out",
                          "--pings", "1", "--no-plots"], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert not scratch.exists()
    assert not [p.name for p in tmp_path.iterdir() if ".tmp-" in p.name]


def test_a_cold_run_has_its_beam_figures_drawn_and_cached(tmp_path):
    """With an empty geometry cache the run draws beams/ (the same pixels as drawing here) and
    caches them, so the next run copies them."""
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
