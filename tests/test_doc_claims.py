"""What users read must be true (issue 27, class 9): the claims of docs that a test of the physics
or of the harness backs, kept in step with it."""
from __future__ import annotations

import importlib.util
import re
import sys

from .conftest import ROOT


def test_scenes_doc_says_a_crest_focuses_and_a_trough_spreads():
    """tests/test_sea_surface.py shows a positive curvature z_xx (a crest, z down) raises the
    bounce's level (the mirror focuses); the doc must say the same, not the reverse."""
    text = " ".join((ROOT / "docs" / "scenes.md").read_text().split())
    assert re.search(r"below a crest \(a mirror concave towards the sonar\) focuses", text)
    assert re.search(r"a trough \(convex\) spreads it", text)
    assert not re.search(r"crest[^.]{0,60}spreads", text)
    assert not re.search(r"trough[^.]{0,40}focuses", text)


def _reliability():
    spec = importlib.util.spec_from_file_location("reliability", ROOT / "benchmarks" / "reliability.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["reliability"] = module
    spec.loader.exec_module(module)
    return module


def test_no_reliability_probe_is_refused_for_a_key_its_own_yaml_writes_twice():
    """docs/reliability.md counted probes refused for a duplicate key in the probe's own scene,
    not for what they name (21 of them): only the probes of malformed YAML may write a key
    twice, and they say so in their names."""
    rel = _reliability()
    twice = []
    for p in rel.probes():
        for name, content in p.files.items():
            if isinstance(content, str) and name.endswith((".yaml", ".yml")):
                tops = re.findall(r"^([A-Za-z_]\w*):", content.split("\n---")[0], re.M)
                if len(tops) != len(set(tops)) and p.name != "duplicate key":
                    twice.append(f"{p.cls}: {p.name}")
    assert twice == []
