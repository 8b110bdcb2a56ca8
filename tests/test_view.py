"""``abacus view`` off screen: no warning from pyvista or VTK, and a picture the scene fills."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

from .conftest import ROOT



def test_view_off_screen_warns_of_nothing_and_fills_its_picture(tmp_path):
    """A sideways fan under a swell (the scene that left half the picture empty), with no X
    display: every Python warning shown (``-W always``) and VTK's own log on stderr, none
    printed; the drawing (anything not white) spans most of the picture's height and width."""
    from PIL import Image
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY",
                                                            "VTK_DEFAULT_OPENGL_WINDOW")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    r = subprocess.run([sys.executable, "-W", "always", "-m", "abacus", "view", "swell_ghost",
                        "--ping", "8", "-o", "v.png"], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip() == "", r.stderr        # no "warning: ...", no VTK "WARN|"
    img = np.asarray(Image.open(tmp_path / "v.png").convert("L"))
    drawn = img < 245
    rows, cols = np.flatnonzero(drawn.any(axis=1)), np.flatnonzero(drawn.any(axis=0))
    assert (rows[-1] - rows[0]) / img.shape[0] > 0.8 and (cols[-1] - cols[0]) / img.shape[1] > 0.8
    # below the legend (the top 270 pixels), the scene's drawing fills its rows
    body = drawn[300:]
    assert body.any(axis=1).mean() > 0.7
