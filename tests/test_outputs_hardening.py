"""Issue 27, classes 6, 7 and 8 and the "did you mean" suggestions: `abacus convert` writes only
what processing can read, machine-readable outputs are strict, and a command's set of outputs
appears whole or not at all — under errors, a full disk and signals. Every refusal is checked
the way a user meets it: the exit status, exactly one line on stderr naming the file, field or
option and what is accepted, no traceback, nothing left behind in the folder."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest
import scipy.io

import acoustics
import processing
from processing.base.dataset import ELEMENT_GROUP, open_tree

from .test_cli import abacus
from .test_interop import _legacy, _recording


# ------------------------------------------------------------------ helpers
def _refused(r, *words, code=2):
    """Exit ``code``, one line on stderr holding every word, no traceback."""
    assert r.returncode == code, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def _files(folder):
    """Every name in a folder, hidden temporaries included."""
    return sorted(os.listdir(folder))


def _strict_json(text):
    """json.loads that refuses NaN, Infinity and -Infinity (what JSON readers other than
    Python's do)."""
    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")
    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Three pings of two targets, written once."""
    folder = tmp_path_factory.mktemp("data")
    tree = acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(3))
    processing.write_tree(tree, folder / "s.nc")
    return folder / "s.nc"


@pytest.fixture
def work(tmp_path, dataset):
    """A fresh folder holding the dataset as s.nc."""
    shutil.copy(dataset, tmp_path / "s.nc")
    return tmp_path


# ------------------------------------------- class 6: convert as strict as the readers
@pytest.mark.parametrize("override, words", [
    ({"ping_time": np.array([0.0, np.nan])}, ["ping_time", "NaN"]),
    ({"ping_time": np.array([1.0, 0.5])}, ["ping_time", "must increase", "ping 1"]),
    ({"ping_time": np.array([0.0, 0.0])}, ["ping_time", "must increase"]),
    ({"ping_time": np.array([0.0, 1e12])}, ["ping_time", "100 years"]),
    ({"c": 1e12}, ["'c'", "1300–1800 m/s"]),
    ({"c": 340.0}, ["'c'", "1300–1800 m/s"]),
    ({"replica": np.zeros(16, complex)}, ["'replica'", "all zero"]),
    ({"replica": np.zeros(0)}, ["'replica'", "empty"]),
    ({"element_subarray": np.array(list("C" * 16))}, ["element_subarray", "'C'", "'A' or 'B'"]),
    ({"element_subarray": np.array(list("A" * 16))}, ["interferometric", "A and B", "normal"]),
    ({"fs": "fast"}, ["'fs'", "text"]),
    ({"element_xyz": "somewhere"}, ["'element_xyz'", "text"]),
    ({"replica": "chirp"}, ["'replica'", "text"]),
    ({"tx_weight": np.zeros(8)}, ["tx_weight", "all zero"]),
    ({"bandwidth": 1e6}, ["'bandwidth'", "sampling rate"]),
])
def test_convert_refuses_what_processing_cannot_use(tmp_path, override, words):
    _recording(tmp_path / "bad.mat", pings=2, **override)
    before = _files(tmp_path)
    r = abacus("convert", "bad.mat", "out.nc", cwd=tmp_path)
    _refused(r, "bad.mat", *words)
    assert _files(tmp_path) == before


def test_convert_text_samples_are_one_line_not_a_crash(tmp_path):
    _recording(tmp_path / "bad.mat", pings=1)
    m = scipy.io.loadmat(tmp_path / "bad.mat")
    m = {k: v for k, v in m.items() if not k.startswith("__") and k != "samples"}
    m.update(samples_r="abc", samples_i="def")
    scipy.io.savemat(tmp_path / "bad.mat", m)
    _refused(abacus("convert", "bad.mat", "out.nc", cwd=tmp_path), "'samples_r'", "text")
    assert not (tmp_path / "out.nc").exists()


def test_convert_names_every_missing_mat_field_at_once(tmp_path):
    _recording(tmp_path / "bad.mat", pings=1, fs=None, c=None, tx_xyz=None)
    line = _refused(abacus("convert", "bad.mat", "out.nc", cwd=tmp_path), "missing fields")
    assert all(f"'{k}'" in line for k in ("fs", "c", "tx_xyz"))


@pytest.mark.parametrize("form", [
    "AAAAAAAABBBBBBBB",                                   # MATLAB's char row 'AAAA...BBBB'
    np.array(list("AAAAAAAABBBBBBBB"))[:, None],          # n x 1 chars
    np.array(["AAAAAAAA", "BBBBBBBB"]),                   # a char matrix, read row by row
])
def test_convert_accepts_the_matlab_char_forms_of_element_subarray(tmp_path, form):
    _recording(tmp_path / "rec.mat", pings=1, element_subarray=form)
    r = abacus("convert", "rec.mat", "rec.nc", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    sub = open_tree(tmp_path / "rec.nc")[ELEMENT_GROUP].ds["element_subarray"].values.astype(str)
    assert "".join(sub) == "A" * 8 + "B" * 8


def test_convert_of_one_subarray_in_normal_mode_is_accepted(tmp_path):
    _recording(tmp_path / "rec.mat", pings=1, element_subarray=np.array(list("A" * 16)), mode="normal")
    assert abacus("convert", "rec.mat", "rec.nc", cwd=tmp_path).returncode == 0


def test_convert_names_every_field_the_previous_layout_lacks_at_once(work):
    tree = open_tree(work / "s.nc")
    old = _legacy(tree)
    eg = old["Simulation/Element_group1"]
    eg.dataset = eg.to_dataset(inherit=False).drop_vars(["sample_interval", "element_subarray"])
    old["Sonar"].dataset = old["Sonar"].to_dataset(inherit=False).drop_vars(["replica_r", "replica_i"])
    old.to_netcdf(work / "old.nc")
    line = _refused(abacus("convert", "old.nc", "conv.nc", cwd=work), "old.nc", "lacks 4 variables")
    for name in ("sample_interval", "element_subarray", "/Sonar/replica_r", "/Sonar/replica_i"):
        assert name in line
    assert not (work / "conv.nc").exists()


def test_convert_of_the_previous_layout_with_decreasing_times_is_refused(work):
    old = _legacy(open_tree(work / "s.nc"))
    eg = old["Simulation/Element_group1"].to_dataset(inherit=False)
    old["Simulation/Element_group1"].dataset = eg.assign_coords(ping_time=eg["ping_time"].values[::-1])
    old.to_netcdf(work / "old.nc")
    _refused(abacus("convert", "old.nc", "conv.nc", cwd=work), "old.nc", "ping_time", "increase")


def test_convert_of_a_fifo_is_refused_without_opening_it(tmp_path):
    os.mkfifo(tmp_path / "rec.mat")
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-c", "import sys; from abacus.cli import main; "
                        "sys.exit(main(['convert', 'rec.mat', 'out.nc']))"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert time.monotonic() - t0 < 30
    _refused(r, "rec.mat", "FIFO")
    assert _files(tmp_path) == ["rec.mat"]


def test_convert_onto_its_own_input_is_refused_even_with_overwrite(tmp_path):
    _recording(tmp_path / "rec.mat", pings=1)
    abacus("convert", "rec.mat", "rec.nc", cwd=tmp_path)
    os.symlink("rec.nc", tmp_path / "alias.nc")
    data = (tmp_path / "rec.nc").read_bytes()
    _refused(abacus("convert", "alias.nc", "rec.nc", "--overwrite", cwd=tmp_path),
             "rec.nc", "is the input", "--overwrite")
    assert (tmp_path / "rec.nc").read_bytes() == data


# ------------------------------------------------ class 7: outputs a program can read
def test_track_json_of_one_ping_is_strict_json(tmp_path):
    tree = acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(1))
    processing.write_tree(tree, tmp_path / "one.nc")
    r = abacus("track", "one.nc", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "NaN" not in r.stdout and "Infinity" not in r.stdout
    out = _strict_json(r.stdout)
    assert out["summary"]["track_density_per_m3"] is None        # no duration: no density
    r = abacus("track", "one.nc", cwd=tmp_path)
    assert r.returncode == 0 and "track density – m⁻³" in r.stdout


def test_track_json_has_no_nan_anywhere(work):
    r = abacus("track", "s.nc", "--json", cwd=work)
    assert r.returncode == 0, r.stderr
    _strict_json(r.stdout)


def test_track_refuses_decreasing_ping_times(work):
    import xarray as xr
    t = xr.open_datatree(work / "s.nc").load()
    eg = t[ELEMENT_GROUP].to_dataset(inherit=False)
    t[ELEMENT_GROUP].dataset = eg.assign_coords(ping_time=eg["ping_time"].values[[0, 2, 1]])
    t.to_netcdf(work / "back.nc")
    before = _files(work)
    _refused(abacus("track", "back.nc", "--json", "-o", "tr.nc", cwd=work),
             "back.nc", "ping_time", "ping 2", "time order")
    assert _files(work) == before


@pytest.mark.parametrize("layer, words", [
    ("100:120", ["outside the image"]),
    ("20:20.0001", ["thinner than the image's range cells"]),
])
def test_sv_of_a_layer_without_cells_is_refused_not_nasc_zero(work, layer, words):
    r = abacus("sv", "s.nc", "--layer", layer, "--json", "--nasc-csv", "n.csv", cwd=work)
    line = _refused(r, f"--layer {layer}", "the image covers", *words)
    assert " m in cells of " in line
    assert _files(work) == ["s.nc"]


def test_sv_of_a_layer_inside_the_image_gives_its_nasc(work):
    r = abacus("sv", "s.nc", "--layer", "15:22", "--json", cwd=work)
    assert r.returncode == 0, r.stderr
    assert _strict_json(r.stdout)["layers"][0]["NASC_mean_m2_nmi2"] > 0


@pytest.mark.parametrize("option", [["--range-bin", "1e-9"], ["--range-bin", "1e-5", "--max-memory", "0.2"]])
def test_sv_with_an_absurdly_fine_range_bin_is_refused_before_allocating(work, option):
    t0 = time.monotonic()
    r = abacus("sv", "s.nc", *option, "--csv", "m.csv", cwd=work)
    _refused(r, "range bin", "memory limit", code=3)
    assert time.monotonic() - t0 < 60
    assert _files(work) == ["s.nc"]


@pytest.mark.parametrize("value", ["nan", "inf", "0", "-1"])
def test_sv_range_bin_must_be_a_positive_finite_number(work, value):
    _refused(abacus("sv", "s.nc", f"--range-bin={value}", cwd=work), "--range-bin", "positive")


# ------------------------------------------------- class 8: all outputs or none
FAIL_TARGETS_CSV = ("import processing.backscatter.target_table as T\n"
                    "def boom(tree, path, settings=None):\n"
                    "    open(path, 'w').write('half')\n"
                    "    raise RuntimeError('the third output failed')\n"
                    "T.write_single_targets_csv = boom")


def test_count_leaves_no_output_when_a_later_one_fails(work):
    r = abacus("count", "s.nc", "-o", "c.nc", "--csv", "d.csv", "--targets-csv", "t.csv", cwd=work,
               pre=FAIL_TARGETS_CSV)
    assert r.returncode == 1 and "the third output failed" in r.stderr
    assert _files(work) == ["s.nc"]


def test_count_with_overwrite_keeps_the_previous_outputs_when_a_later_one_fails(work):
    for name in ("c.nc", "d.csv", "t.csv"):
        (work / name).write_text("previous")
    r = abacus("count", "s.nc", "-o", "c.nc", "--csv", "d.csv", "--targets-csv", "t.csv", "--overwrite",
               cwd=work, pre=FAIL_TARGETS_CSV)
    assert r.returncode == 1
    assert _files(work) == ["c.nc", "d.csv", "s.nc", "t.csv"]
    assert all((work / n).read_text() == "previous" for n in ("c.nc", "d.csv", "t.csv"))


def test_count_writes_the_whole_set_when_nothing_fails(work):
    r = abacus("count", "s.nc", "-o", "c.nc", "--csv", "d.csv", "--targets-csv", "t.csv", "--json", cwd=work)
    assert r.returncode == 0, r.stderr
    _strict_json(r.stdout)
    assert _files(work) == ["c.nc", "d.csv", "s.nc", "t.csv"]


@pytest.mark.parametrize("sig, status, word", [("SIGINT", 130, "interrupted"), ("SIGTERM", 143, "terminated")])
def test_count_interrupted_between_two_outputs_leaves_none(work, sig, status, word):
    pre = ("import os, signal, processing.base.atomic as A\n"
           "import processing.backscatter.target_table as T\n"
           "real = T.write_single_targets_csv\n"
           "def interrupted(tree, path, settings=None):\n"
           "    real(tree, path, settings)\n"
           f"    os.kill(os.getpid(), signal.{sig})\n"
           "    import time; time.sleep(3)\n"
           "T.write_single_targets_csv = interrupted")
    r = abacus("count", "s.nc", "-o", "c.nc", "--csv", "d.csv", "--targets-csv", "t.csv", "--plots", "p",
               cwd=work, pre=pre)
    assert r.returncode == status and r.stderr.strip() == word, r.stderr
    assert _files(work) == ["s.nc"]


def test_track_leaves_no_output_when_its_plots_fail(work):
    pre = ("import abacus.figures.tracks as F\n"
           "def boom(tree, outdir):\n"
           "    raise RuntimeError('drawing failed')\n"
           "F.track_figures = boom")
    r = abacus("track", "s.nc", "-o", "t.nc", "--csv", "t.csv", "--plots", "p", cwd=work, pre=pre)
    assert r.returncode == 1 and "drawing failed" in r.stderr
    assert _files(work) == ["s.nc"]


def test_track_writes_its_whole_set(work):
    r = abacus("track", "s.nc", "-o", "t.nc", "--csv", "t.csv", "--plots", "p", cwd=work)
    assert r.returncode == 0, r.stderr
    assert _files(work) == ["p", "s.nc", "t.csv", "t.nc"]
    assert any(f.suffix == ".png" for f in (work / "p").iterdir())


#: SIGTERM delivered while xarray's netCDF writer holds part of its locks (inside
#: CombinedLock.acquire): the exception left a lock held and the writer's clean-up waited on it
#: until the 5 s watchdog killed the process, which said 'interrupted' for a SIGTERM
SIGTERM_INSIDE_THE_WRITER = """
import os, signal
from xarray.backends import locks
import processing.base.dataset as D
real_acquire, real_write = locks.acquire, D.write_tree
state = {"armed": False, "n": 0}
def acquire(lock, blocking=True):
    out = real_acquire(lock, blocking)
    if state["armed"]:
        state["n"] += 1
        if state["n"] == 101:
            state["armed"] = False
            import time
            open(SIGNALLED_AT, "w").write(repr(time.time()))
            os.kill(os.getpid(), signal.SIGTERM)
    return out
def write_tree(*a, **k):
    state["armed"] = True
    try:
        return real_write(*a, **k)
    finally:
        state["armed"] = False
locks.acquire, D.write_tree = acquire, write_tree
"""


def test_sigterm_inside_the_netcdf_writer_ends_at_once_as_terminated(work):
    stamp = work.parent / f"{work.name}.signalled"
    pre = f"SIGNALLED_AT = {str(stamp)!r}\n" + SIGTERM_INSIDE_THE_WRITER.strip()
    r = abacus("count", "s.nc", "-o", "c.nc", "--csv", "d.csv", cwd=work, pre=pre)
    elapsed = time.time() - float(stamp.read_text())
    assert r.returncode == 143 and r.stderr.strip() == "terminated", r.stderr
    assert elapsed < 4.0, elapsed              # not the 5 s watchdog
    assert _files(work) == ["s.nc"]


def test_the_watchdog_ends_a_stuck_command_by_its_signal_with_the_right_word(work):
    """A command that does not end within 5 s of SIGTERM (here: it ignores the exception) is
    ended by the signal itself (143), saying 'terminated', not 'interrupted'."""
    pre = ("import os, signal, threading, time, abacus.cli.count as C\n"
           "def stuck(args):\n"
           "    threading.Timer(0.2, lambda: os.kill(os.getpid(), signal.SIGTERM)).start()\n"
           "    end = time.monotonic() + 30\n"
           "    while time.monotonic() < end:\n"
           "        try:\n"
           "            time.sleep(0.05)\n"
           "        except BaseException:\n"
           "            pass\n"
           "    return 0\n"
           "C.command = stuck")
    t0 = time.monotonic()
    r = abacus("count", "s.nc", cwd=work, pre=pre)
    assert time.monotonic() - t0 < 15
    assert r.returncode == -15 and r.stderr.strip() == "terminated", (r.returncode, r.stderr)


def test_a_full_disk_during_a_netcdf_write_is_status_5_and_leaves_nothing(work):
    """The free-space check passed (here: bypassed), the write then meets the file size limit:
    HDF5 says only 'NetCDF: HDF error'; the command says what the machine refused."""
    pre = ("import resource, abacus.cli.common as C\n"
           "C.check_room = lambda *a, **k: None\n"
           "resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 20, 1 << 20))")
    r = abacus("count", "s.nc", "-o", "c.nc", "--csv", "d.csv", cwd=work, pre=pre)
    _refused(r, "c.nc", "File too large", "nothing was left half-written", code=5)
    assert _files(work) == ["s.nc"]


def _tmpfs(folder, kb):
    folder.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={kb}k", "tmpfs", str(folder)],
                          capture_output=True).returncode == 0


def test_a_full_filesystem_is_refused_up_front_or_status_5(work):
    disk = work / "disk"
    if not _tmpfs(disk, 1024):
        pytest.skip("no permission to mount a small tmpfs")
    try:
        r = abacus("count", "s.nc", "-o", "disk/c.nc", cwd=work)
        _refused(r, "disk/c.nc", "free", code=3)                   # the free-space check
        r = abacus("count", "s.nc", "-o", "disk/c.nc", "--csv", "disk/d.csv", cwd=work,
                   pre="import abacus.cli.common as C; C.check_room = lambda *a, **k: None")
        _refused(r, "disk/c.nc", "No space left on device", "nothing was left half-written", code=5)
        assert _files(disk) == []
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


@pytest.mark.parametrize("args, words", [
    (["count", "s.nc", "-o", "s.nc", "--overwrite"], ["-o s.nc", "is the input s.nc"]),
    (["count", "link.nc", "-o", "s.nc", "--overwrite"], ["-o s.nc", "is the input link.nc"]),
    (["count", "s.nc", "--csv", "s.nc", "--overwrite"], ["--csv s.nc", "is the input"]),
    (["count", "s.nc", "--settings", "p.yaml", "--csv", "p.yaml", "--overwrite"], ["--csv p.yaml", "is the input"]),
    (["count", "d/s.nc", "--plots", "d", "--overwrite"], ["--plots d", "holds the input d/s.nc"]),
    (["sv", "s.nc", "--nasc-csv", "s.nc", "--overwrite"], ["--nasc-csv s.nc", "is the input"]),
    (["track", "s.nc", "-o", "s.nc", "--overwrite"], ["-o s.nc", "is the input"]),
    (["image", "s.nc", "-o", "s.nc", "--overwrite"], ["-o s.nc", "is the input"]),
    (["count", "s.nc", "--csv", "x.csv", "--targets-csv", "x.csv"], ["--targets-csv x.csv", "also given to --csv"]),
])
def test_an_output_equal_to_an_input_is_refused_even_with_overwrite(work, args, words):
    os.symlink("s.nc", work / "link.nc")
    (work / "d").mkdir()
    shutil.copy(work / "s.nc", work / "d" / "s.nc")
    (work / "p.yaml").write_text("detect: {}\n")
    data = (work / "s.nc").read_bytes()
    before = _files(work)
    _refused(abacus(*args, cwd=work), *words)
    assert (work / "s.nc").read_bytes() == data and (work / "d" / "s.nc").exists()
    assert _files(work) == before


def test_an_unreachable_scheduler_leaves_no_folder_and_says_so(tmp_path):
    r = abacus("experiment", "two_targets", "-o", "exp", "--pings", "1", "--scheduler", "tcp://127.0.0.1:1",
               cwd=tmp_path)
    line = _refused(r, "--scheduler tcp://127.0.0.1:1", "no Dask scheduler answered", "nothing was written")
    assert "half-written" not in line
    assert _files(tmp_path) == []


# ------------------------------------------------------------------ did you mean
@pytest.mark.parametrize("args, suggestion", [
    (["rnu", "default"], "did you mean 'run'?"),
    (["simualte", "default", "-o", "x.nc"], "did you mean 'simulate'?"),
    (["scene", "chek", "default"], "did you mean 'check'?"),
    (["run", "defualt"], "did you mean 'default'?"),
    (["scene", "check", "two_target"], "did you mean 'two_targets'?"),
])
def test_a_mistyped_command_or_scene_gets_a_suggestion(tmp_path, args, suggestion):
    _refused(abacus(*args, cwd=tmp_path), suggestion)
    assert _files(tmp_path) == []


def test_no_suggestion_when_nothing_is_close(tmp_path):
    line = _refused(abacus("xyzzy", cwd=tmp_path), "invalid choice")
    assert "did you mean" not in line
    line = _refused(abacus("scene", "check", "qqqqqq", cwd=tmp_path), "built-in scenes:")
    assert "did you mean" not in line


# ------------------------------------------------------------ signals, early and disguised
@pytest.mark.parametrize("sig, status, word", [("SIGINT", 130, "interrupted"), ("SIGTERM", 143, "terminated")])
def test_an_interrupt_while_the_commands_load_is_an_interrupt_not_a_traceback(tmp_path, sig, status, word):
    pre = ("import os, signal, time, abacus.cli.app as A\n"
           "real = A.build_parser\n"
           "def build_parser():\n"
           f"    os.kill(os.getpid(), signal.{sig})\n"
           "    time.sleep(2)\n"
           "    return real()\n"
           "A.build_parser = build_parser")
    r = abacus("beams", "--json", cwd=tmp_path, pre=pre)
    assert r.returncode == status and r.stderr.strip() == word, (r.returncode, r.stderr)


def test_an_interrupt_a_reader_turned_into_a_dataset_error_still_ends_as_the_interrupt(work):
    """A reader that wraps any exception as "damaged or truncated (...)" — an interrupt landing
    in a library it calls is one — must not turn Ctrl-C into "error: ... damaged"."""
    pre = ("import os, signal, time, processing.base.dataset as D\n"
           "def open_tree(path, **kw):\n"
           "    try:\n"
           "        os.kill(os.getpid(), signal.SIGINT)\n"
           "        time.sleep(2)\n"
           "    except BaseException as exc:\n"
           "        raise D.DatasetError(f'{path}: damaged or truncated ({exc.__class__.__name__}: )') from None\n"
           "D.open_tree = open_tree")
    r = abacus("count", "s.nc", "-o", "c.nc", cwd=work, pre=pre)
    assert r.returncode == 130 and r.stderr.strip() == "interrupted", (r.returncode, r.stderr)
    assert _files(work) == ["s.nc"]
