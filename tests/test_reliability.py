"""Hardening, tested the way a careful user breaks things: the probes of
benchmarks/reliability.py (bad inputs, bad options, real SIGINT/SIGTERM/SIGKILL of a running
command, a full disk, an alias bomb under a memory limit). Every probe must end clean: a short
message and the documented exit status, no traceback, nothing left behind, interrupts within 5 s.
The whole set (190+ probes) regenerates docs/reliability.md; here every probe of the classes
below (the signals, the full disk, the memory limit, what a scene may read) and the first two of
every other class."""
from __future__ import annotations

import importlib.util
import sys

from .conftest import ROOT

_spec = importlib.util.spec_from_file_location("reliability", ROOT / "benchmarks" / "reliability.py")
reliability = importlib.util.module_from_spec(_spec)
sys.modules["reliability"] = reliability
_spec.loader.exec_module(reliability)

WHOLE = {"interrupts", "resources", "paths"}


def _chosen():
    seen: dict = {}
    out = []
    for p in reliability.probes():
        if p.cls in WHOLE or seen.get(p.cls, 0) < 2:
            out.append(p)
        seen[p.cls] = seen.get(p.cls, 0) + 1
    return out


def test_probes_end_clean():
    reliability.prepare()
    results = reliability.run_probes(_chosen())
    bad = [f"{r.probe.cls}: {r.probe.name}: {r.verdict}: {r.reason} | {r.stderr.strip()[-300:]}"
           for r in results if r.verdict != "clean"]
    assert len(results) >= 45
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
