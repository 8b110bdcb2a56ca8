"""Mesh repair without networkx (not a dependency of abacus): a flipped face's winding is made
consistent, as trimesh's own repair (which needs networkx) makes it."""
from __future__ import annotations

import sys

import numpy as np
import pytest
import trimesh

from acoustics.paths.meshes import _fix_winding


def _flipped(mesh, fraction=0.3, seed=4):
    rng = np.random.default_rng(seed)
    faces = mesh.faces.copy()
    pick = rng.random(len(faces)) < fraction
    pick[0] = False                       # the patch's first face sets the winding
    faces[pick] = faces[pick][:, ::-1]
    return trimesh.Trimesh(mesh.vertices, faces, process=False)


@pytest.mark.parametrize("make", [lambda: trimesh.creation.icosphere(subdivisions=2),
                                  lambda: trimesh.creation.box(),
                                  lambda: trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],
                                                          [[0, 1, 2], [1, 3, 2]], process=False)])
def test_winding_made_consistent_without_networkx(make, monkeypatch):
    good = make()
    bad = _flipped(good)
    if len(good.faces) > 2:
        assert not bad.is_winding_consistent
    monkeypatch.setitem(sys.modules, "networkx", None)      # as in a minimal install
    _fix_winding(bad)
    assert bad.is_winding_consistent
    # the first face kept its winding, so every face is back to the original's
    np.testing.assert_array_equal(np.sort(bad.face_normals.round(9), axis=0),
                                  np.sort(good.face_normals.round(9), axis=0))


_RISING = """\
name: rising
sampling: {samples: 1024, time_offset_s: 0.017}
sonar: {pose: {position_m: [0, 0, 5], boresight: [1, 0, 0], receiver_axis: [0, 1, 0]}}
targets:
  points:
    - {frame: world, position_m: [17, 0, 2], velocity_m_s: [0, 0, -0.5]}
boundaries:
  - name: sea
    role: surface
    mesh: {shape: swell, center_m: [15, 0], size_m: [40, 16], resolution_m: 0.5,
           waves: [{amplitude_m: 0.2, wavelength_m: 25}]}
pings: {count: 4, interval_s: 0.25}
processing: {detect: {method: fraction_of_peak, fraction: 0.2}}
"""


def test_more_pings_than_the_scene_has_pass_the_scene_checks_too(tmp_path):
    """A target rising at 0.5 m/s from 2 m depth is in the water for the scene's 4 pings and
    leaves it by ping 39: `--pings 40` must be refused as the scene with 40 pings would be."""
    import subprocess
    (tmp_path / "s.yaml").write_text(_RISING)
    ok = subprocess.run([sys.executable, "-m", "abacus", "scene", "check", "s.yaml"], cwd=tmp_path,
                        capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    r = subprocess.run([sys.executable, "-m", "abacus", "simulate", "s.yaml", "--pings", "40", "-o", "s.nc"],
                       cwd=tmp_path, capture_output=True, text=True)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--pings 40" in lines[0] and "targets.points[0]" in lines[0]
    assert "Traceback" not in r.stderr and not (tmp_path / "s.nc").exists()
