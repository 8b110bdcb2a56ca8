"""docs/figures/labels_ghosts.png: the image of two targets under a flat sea beside its label
cube (the scene of tests/test_labels.py): each target, its surface ghosts and target A's
grating-lobe ghost, named with the target they belong to.

    python benchmarks/labels_figure.py
"""
from __future__ import annotations

import re

from _report import ROOT

import acoustics
import processing
from abacus.figures.labels import draw_label_figure
from acoustics.scene.load import scene_from_text


def main():
    text = re.search(r'GHOSTS = """(.*?)"""', (ROOT / "tests" / "test_labels.py").read_text(), re.S).group(1)
    tree = acoustics.simulate(scene_from_text(text), pings=1)
    out = processing.image(tree, labels=True)
    im = processing.images_of(out)
    lab = out["Processing/Labels"].ds
    path = draw_label_figure(im.image[0, 0], lab["label_class"].values[0, 0], lab["label_id"].values[0, 0],
                             lab["label_fraction"].values[0, 0], im.range_m, im.beam_angle_rad,
                             ROOT / "docs" / "figures" / "labels_ghosts.png",
                             title="two targets under a flat sea")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
