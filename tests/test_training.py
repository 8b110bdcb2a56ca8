"""The training-data recipe (docs/training.md): `abacus dataset` writes images and label cubes
of drawn scenes, and the page's loading block runs verbatim on them."""
from __future__ import annotations

import re

import numpy as np

from abacus.training import draw_scene

from .conftest import ROOT


def test_recipe_runs_and_the_loading_snippet_works(tmp_path, monkeypatch, capsys):
    from abacus.cli.app import main
    monkeypatch.chdir(tmp_path)
    assert main(["dataset", "-o", "training", "--scenes", "2", "--seed", "1"]) == 0
    names = sorted(p.name for p in (tmp_path / "training").iterdir())
    assert names == ["index.csv", "sample_00000.npz", "sample_00000.yaml", "sample_00001.npz",
                     "sample_00001.yaml"]
    text = (ROOT / "docs" / "training.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 1
    ns: dict = {}
    exec(compile(blocks[0], "docs/training.md", "exec"), ns)
    x, y, image, label = ns["x"], ns["y"], ns["image"], ns["label"]
    assert x.shape == y.shape and x.shape[:2] == (2, 1) and image.shape == label.shape == x.shape[1:]
    # every school's fish are labelled somewhere, and their ids are the school's (population 0)
    for f in ns["files"]:
        with np.load(f) as s:
            ids = s["label_id"][s["label_class"] == 1]
            assert ids.size and np.all((ids >= 1_000_000) & (ids < 2_000_000))


def test_scenes_are_a_function_of_seed_and_index():
    assert draw_scene(5, 3) == draw_scene(5, 3)
    assert draw_scene(5, 3)[0] != draw_scene(5, 4)[0] and draw_scene(5, 3)[0] != draw_scene(6, 3)[0]
    seas = {draw_scene(11, i)[1]["sea"] for i in range(30)}
    assert seas == {"flat", "swell", "wind_sea"}


def test_floors_are_drawn():
    floors = {draw_scene(11, i)[1]["floor"] for i in range(40)}
    assert floors == {"silt", "sand", "gravel", "limestone"}
