"""Hardening, tested the way a careful user breaks things: the probes of
benchmarks/reliability.py (bad inputs, bad options, real SIGINT/SIGTERM/SIGKILL of a running
command, a full disk, an alias bomb under a memory limit). Every probe must end clean: a short
message and the documented exit status, no traceback, nothing left behind, interrupts within 5 s.
The whole set (190+ probes) regenerates docs/reliability.md; here every probe of the classes
below (the signals, the full disk, the memory limit, what a scene may read) and the first two of
every other class.

The harness runs in a process of its own: its threads, the commands it forks and the damaged
datasets it writes share nothing with what the suite's earlier tests left in this one (a crash
of the harness is then this test's failure, with its trace, not the suite's end)."""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

from .conftest import ROOT

HARNESS = ROOT / "benchmarks" / "reliability.py"
_spec = importlib.util.spec_from_file_location("reliability", HARNESS)
reliability = importlib.util.module_from_spec(_spec)
sys.modules["reliability"] = reliability
_spec.loader.exec_module(reliability)


def test_probes_end_clean():
    r = subprocess.run([sys.executable, "-X", "faulthandler", str(HARNESS), "--suite"],
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, f"the harness ended with {r.returncode}: {r.stderr[-3000:]}"
    results = json.loads(r.stdout.strip().splitlines()[-1])
    bad = [f"{x['cls']}: {x['name']}: {x['verdict']}: {x['reason']} | {x['stderr']}"
           for x in results if x["verdict"] != "clean"]
    assert len(results) == len(reliability.suite_probes()) >= 45
    assert {x["cls"] for x in results} >= reliability.SUITE_WHOLE
    assert bad == []


def test_there_are_at_least_150_probes_in_every_class_we_promised():
    classes = {p.cls for p in reliability.probes()}
    assert len(reliability.probes()) >= 150
    assert {"yaml_bombs", "impossible_sizes", "impossible_physics", "paths", "interrupts",
            "resources", "experiment_state", "output_collisions", "bad_datasets"} <= classes
    # issue 27's classes: motion files, files out of bounds, size drivers, values the scene check
    # must catch, the moving sea, convert, outputs a program reads, sets of outputs
    assert {"motion_files", "user_files", "size_drivers", "checked_values", "out_of_water", "convert",
            "outputs", "output_sets"} <= classes
