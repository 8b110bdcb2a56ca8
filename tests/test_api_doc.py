"""docs/api.md runs verbatim: every ```python block, in order, in one namespace."""
from __future__ import annotations

import re

from .conftest import ROOT


def test_api_tour_runs_verbatim(tmp_path, monkeypatch):
    text = (ROOT / "docs" / "api.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 5
    monkeypatch.chdir(tmp_path)          # an empty folder, as a new user's
    namespace: dict = {}
    for i, block in enumerate(blocks):
        exec(compile(block, f"docs/api.md block {i + 1}", "exec"), namespace)
    assert (tmp_path / "two.nc").is_file()
