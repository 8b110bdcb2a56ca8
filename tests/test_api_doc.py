"""docs/api.md runs verbatim: every ```python block, in order, in one namespace."""
from __future__ import annotations

import re
import shutil

from .conftest import ROOT


def test_api_tour_runs_verbatim(tmp_path, monkeypatch):
    text = (ROOT / "docs" / "api.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 5
    # a new user's folder, with the scene files of a checkout (the page loads one by its path)
    shutil.copytree(ROOT / "scenes", tmp_path / "scenes")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for i, block in enumerate(blocks):
        exec(compile(block, f"docs/api.md block {i + 1}", "exec"), namespace)
    assert (tmp_path / "two.nc").is_file() and (tmp_path / "exp" / "results.nc").is_file()
