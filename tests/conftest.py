"""Shared fixtures. Every random draw in the tests is seeded."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# the geometry cache of a test session starts empty and lives in a temporary folder: tests never
# see a user's cache, and subprocesses (the CLI) inherit the same folder
_CACHE = None
if "ABACUS_CACHE_DIR" not in os.environ:
    _CACHE = tempfile.mkdtemp(prefix="abacus-test-cache-")
    os.environ["ABACUS_CACHE_DIR"] = _CACHE


@pytest.hookimpl(trylast=True)
def pytest_configure(config):
    """A crash in compiled code prints the stack of the thread that crashed, not every thread's:
    a dump of a run's idle pool threads pushed the crashing one out of CI's excerpt."""
    import faulthandler
    try:
        from _pytest.faulthandler import fault_handler_stderr_fd_key
        fd = config.stash[fault_handler_stderr_fd_key]
    except (ImportError, KeyError):     # another pytest, or its handler turned off: as it is
        return
    faulthandler.enable(file=fd, all_threads=False)


def pytest_sessionfinish(session, exitstatus):
    if _CACHE is not None:
        import shutil
        shutil.rmtree(_CACHE, ignore_errors=True)

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"

#: ABACUS numbers (../shared/reference/ABACUS.md)
C_M_S = 1530.0
F0_HZ = 420_375.0
LAMBDA_M = C_M_S / F0_HZ
K_RAD_M = 2 * np.pi / LAMBDA_M


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def write_scene(tmp_path):
    """Write YAML text to a scene file in a temporary folder; return its path."""
    def _write(text: str, name: str = "scene.yaml") -> Path:
        p = tmp_path / name
        p.write_text(text)
        return p
    return _write


def on_one_thread_and_all(fn):
    """``(fn() on one numba thread, fn() on all of them)``: for the tests that a result does not
    depend on the thread count (the default count is restored whatever ``fn`` does)."""
    import numba
    n = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = fn()
        numba.set_num_threads(n)
        return one, fn()
    finally:
        numba.set_num_threads(n)
