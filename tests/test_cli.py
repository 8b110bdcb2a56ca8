"""The command line as a new user meets it: version, built-in scenes, optional extras."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

import acoustics

from .conftest import ROOT


def abacus(*args, cwd, pre: str = "pass"):
    code = f"{pre}; import sys; from abacus.cli import main; sys.exit(main({list(args)!r}))"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd)


def test_version_is_the_installed_distribution(tmp_path):
    r = abacus("--version", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.strip() == f"abacus {acoustics.__version__}"
    assert acoustics.__version__ != "0+unknown"


def test_builtin_scene_by_name_from_an_empty_folder(tmp_path):
    r = abacus("scene", "check", "two_targets", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "ok" in r.stdout and "two-targets" in r.stdout
    assert list(tmp_path.iterdir()) == []


def test_unknown_scene_lists_the_builtin_ones(tmp_path):
    r = abacus("scene", "check", "no_such_scene", cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "built-in scenes:" in r.stderr and "default" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_beams_json_from_an_empty_folder(tmp_path):
    r = abacus("beams", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    table = json.loads(r.stdout)
    # thesis Table 3.2: the ABACUS transmitter, 10.28° x 0.86° (docs/arrays.md)
    tx = table["transmitter"]["abacus"]["normal"]
    assert abs(tx["azimuth_3db_deg"] - 10.28) < 0.05 and abs(tx["elevation_3db_deg"] - 0.86) < 0.01


def test_view_without_pyvista_says_how_to_get_it(tmp_path):
    r = abacus("view", "two_targets", "-o", "v.png", cwd=tmp_path,
               pre="import sys; sys.modules['pyvista'] = None")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "abacus[view]" in r.stderr
    assert not (tmp_path / "v.png").exists()


def test_python_m_acoustics_is_the_command_line(tmp_path):
    r = subprocess.run([sys.executable, "-m", "abacus", "--version"], capture_output=True,
                       text=True, cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.startswith("abacus ")


def test_scenes_folder_is_the_builtin_scenes():
    from acoustics.scene.builtin import builtin_scenes, scenes_dir
    assert scenes_dir() == (ROOT / "scenes").resolve()
    assert {p.stem for p in (ROOT / "scenes").glob("*.yaml")} == set(builtin_scenes())


def test_an_interrupt_inside_a_compiled_kernel_is_still_an_interrupt(tmp_path):
    """SIGINT landing inside a numba kernel surfaces as ``SystemError: ... returned a result with
    an exception set`` caused by the KeyboardInterrupt: exit 130 'interrupted', not an internal
    error (seen once in the reliability probes)."""
    pre = ("import abacus.cli.beams as b\n"
           "def boom(args):\n"
           "    try:\n"
           "        raise KeyboardInterrupt\n"
           "    except KeyboardInterrupt as e:\n"
           "        raise SystemError('CPUDispatcher returned a result with an exception set') from e\n"
           "b.command = boom")
    r = abacus("beams", "--json", cwd=tmp_path, pre=pre)
    assert r.returncode == 130 and r.stderr.strip() == "interrupted"


def test_an_interrupt_swallowed_by_a_library_still_ends_as_an_interrupt(tmp_path):
    """matplotlib's drawing code can swallow the KeyboardInterrupt of a SIGINT and fail later
    with an unrelated error (seen in the reliability probes: 'Invalid bounding box'): the
    process still ends as interrupted (130), not as an internal error."""
    pre = ("import abacus.cli.beams as b\n"
           "import os, signal\n"
           "def boom(args):\n"
           "    try:\n"
           "        os.kill(os.getpid(), signal.SIGINT)\n"
           "        import time; time.sleep(1)\n"
           "    except KeyboardInterrupt:\n"
           "        pass\n"
           "    raise ValueError('Invalid bounding box')\n"
           "b.command = boom")
    r = abacus("beams", "--json", cwd=tmp_path, pre=pre)
    assert r.returncode == 130 and r.stderr.strip() == "interrupted"


@pytest.mark.parametrize("sig, status, word", [(signal.SIGINT, 130, "interrupted"),
                                                (signal.SIGTERM, 143, "terminated")])
def test_an_interrupt_landing_in_a_finaliser_ends_the_command_as_an_interrupt(tmp_path, sig, status, word):
    """A SIGINT whose KeyboardInterrupt is raised while a ``__del__`` runs is one Python can
    only print ('Exception ignored in ...', a traceback) and drop, and the command would go on
    (seen in the reliability probes: SIGINT during an experiment, during imports): it still
    ends the command as that interrupt, 130 'interrupted' (SIGTERM: 143 'terminated'), with no
    traceback, within its next steps (no exception can leave a finaliser and there is no
    ``os._exit``: the interrupt is raised again once the finaliser is left)."""
    pre = ("import abacus.cli.beams as b\n"
           "import os, signal, threading, time\n"
           "class Finaliser:\n"
           "    def __del__(self):\n"
           "        time.sleep(5)              # the signal lands here\n"
           "def boom(args):\n"
           "    f = Finaliser()\n"
           f"    threading.Timer(0.3, os.kill, (os.getpid(), {int(sig)})).start()\n"
           "    del f\n"
           "    for step in range(50):         # the command's work, which must not go on\n"
           "        time.sleep(0.1)\n"
           "    print('went on')\n"
           "    return 0\n"
           "b.command = boom")
    t0 = time.monotonic()
    r = abacus("beams", "--json", cwd=tmp_path, pre=pre)
    assert r.returncode == status and r.stderr.strip() == word, r.stderr
    assert "went on" not in r.stdout
    assert time.monotonic() - t0 < 4.5      # neither the finaliser's 5 s nor the work's 5 s


def test_an_interrupt_is_not_raised_inside_the_compiler(tmp_path):
    """A KeyboardInterrupt raised inside numba's or llvmlite's Python code (a kernel compiled or
    loaded from its cache) left a dispatcher half made, and the next call crashed the process
    (exit -11, seen in a loop of SIGINTs into `abacus simulate`): a signal landing there is raised
    once that code has returned, and the command still ends with 130 'interrupted'."""
    pre = ("import abacus.cli.beams as b\n"
           "import os, signal, sys, threading, time, types\n"
           "fake = types.ModuleType('numba._abacus_test_compiler')\n"
           "exec('import time\\ndef compile_kernel():\\n'\n"
           "     '    for step in range(60):\\n'\n"
           "     '        time.sleep(0.01)\\n'\n"
           "     '    print(\\'compiled\\', step, flush=True)\\n'\n"
           "     '    return step', fake.__dict__)\n"
           "def boom(args):\n"
           "    threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT)).start()\n"
           "    fake.compile_kernel()           # the signal lands inside\n"
           "    for step in range(300):         # the command's work, which must not go on\n"
           "        time.sleep(0.01)\n"
           "    print('went on')\n"
           "    return 0\n"
           "b.command = boom")
    r = abacus("beams", "--json", cwd=tmp_path, pre=pre)
    assert r.returncode == 130 and r.stderr.strip() == "interrupted", (r.returncode, r.stderr)
    # the compiler's code ran to its end (it prints there: a print after it returns may be cut
    # by the interrupt, delivered then, between its words)
    assert "compiled 59" in r.stdout
    assert "went on" not in r.stdout


def test_an_interrupt_that_left_an_eval_still_ends_python_m_abacus_with_130(tmp_path):
    """A KeyboardInterrupt that passed through an ``eval`` of a string (namedtuple and dataclass
    definitions run one while modules load: seen in the reliability probes) is recorded by
    CPython as unhandled, and ``python -m`` would end the process by SIGINT (-2) after the
    command returned 130; the command still ends with 130 'interrupted'."""
    (tmp_path / "evalcase.py").write_text(
        "import os, signal, sys, threading\n"
        "import abacus.cli.beams as b\n"
        "def boom(args):\n"
        "    threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT)).start()\n"
        "    eval(\"__import__('time').sleep(5)\")   # the signal lands inside the eval\n"
        "    return 0\n"
        "b.command = boom\n"
        "from abacus.cli import main\n"
        "if __name__ == '__main__':\n"
        "    sys.exit(main(['beams', '--json']))\n")
    r = subprocess.run([sys.executable, "-m", "evalcase"], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 130 and r.stderr.strip() == "interrupted", (r.returncode, r.stderr)
