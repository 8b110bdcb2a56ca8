"""count.sidelobe_db: a strong fish's sidelobes are not counted, a weaker real fish is
(processing/detection/sidelobes.py)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import acoustics
import processing
from acoustics.scene import scene_from_text
from processing.base.config import ConfigError
from processing.base.contract import COUNTS_GROUP
from processing.detection.sidelobes import ghost_geometry, psf_sidelobes
from processing.settings import ProcessingSettings

# A strong target on axis (TS -20 dB) and a real one 20 dB weaker (TS -40 dB), 1 m further and two
# beams away: at physical levels and sea noise the strong one's range sidelobes (in its beam, out
# to the 7 ms pulse's 5 m) and azimuth sidelobes (at its range) cross the Rayleigh threshold.
SCENE = """
schema_version: 1
name: strong-and-weak
seed: 5
sonar:
  levels: {{source_level_db: 210.0}}
medium: {{temperature_c: 10.0, salinity_psu: 35.0, depth_m: 30.0}}
noise: {{enabled: true, model: sea}}
targets:
  points:
    - {{range_m: 18.0, azimuth_deg: 0.0, elevation_deg: 0.0, backscatter: {{model: fixed, ts_db: -20.0}}, label: strong}}
    - {{range_m: 19.0, azimuth_deg: 3.0, elevation_deg: 0.0, backscatter: {{model: fixed, ts_db: -40.0}}, label: weak}}
pings: {{count: 2}}
processing:
  image: {{range_m: [14.5, 23.5]}}
  detect:
    method: rayleigh
    pfa_image: 1.0e-6
    noise: {{source: region, range_m: [14.5, 16.5], estimator: ml}}
  count: {{range_m: [17.0, 20.0], sidelobe_db: {sidelobe_db}, ghost_db: {ghost_db}}}
"""


def counts(sidelobe_db, ghost_db=6.0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = processing.count(acoustics.simulate(scene_from_text(SCENE.format(sidelobe_db=sidelobe_db, ghost_db=ghost_db))))
    return tree[COUNTS_GROUP].ds


@pytest.fixture(scope="module")
def both():
    return counts(0, 0), counts(30)


def test_strong_targets_sidelobes_are_counted_without_the_rule(both):
    off, _ = both
    # the reference counts every detection located inside the volume: the two fish and more
    assert (off["true_in_volume"].values == 2).all()
    assert (off["count_after"].values > 2).all()
    assert (off["false_alarms_after"].values > 0).all()


def test_the_rule_counts_both_real_targets_and_no_sidelobe(both):
    _, on = both
    assert (on["count_after"].values == 2).all()
    assert (on["hits_after"].values == 2).all()          # the weak real target is kept
    assert (on["false_alarms_after"].values == 0).all()


def test_psf_rule_geometry():
    """j below i by more than the margin: a sidelobe in i's range main lobe at any azimuth, or in
    i's beam within the pulse's length; not elsewhere, and never when only a little weaker."""
    dr, daz = 0.067, np.radians(2.4)
    ping = [0, 0, 0, 0, 0, 1]
    r = [18.0, 18.1, 22.0, 22.0, 18.05, 18.05]
    az = [0.0, np.radians(20), np.radians(0.5), np.radians(10), np.radians(1), 0.0]
    a = [1e4, 1.0, 1.0, 1.0, 1e3, 1.0]          # the 5th only 20 dB below: kept at 30 dB
    side = psf_sidelobes(ping, r, az, a, range_resolution_m=dr, azimuth_resolution_rad=daz,
                         pulse_range_m=5.2, sidelobe_db=30.0)
    assert side.tolist() == [False, True, True, False, False, False]
    assert not psf_sidelobes(ping, r, az, a, range_resolution_m=dr, azimuth_resolution_rad=daz,
                             pulse_range_m=5.2, sidelobe_db=0.0).any()
    # NaN amplitudes and an empty ping are harmless
    assert psf_sidelobes([], [], [], [], range_resolution_m=dr, azimuth_resolution_rad=daz,
                         pulse_range_m=5.2, sidelobe_db=30.0).size == 0
    nan = psf_sidelobes([0, 0], [18.0, 18.0], [0.0, 0.1], [np.nan, 1.0], range_resolution_m=dr,
                        azimuth_resolution_rad=daz, pulse_range_m=5.2, sidelobe_db=30.0)
    assert not nan.any()


def test_abacus_ghost_geometry_gives_the_thesis_ghosts():
    """ABACUS' subarray A: 8 elements 15 mm apart, alternate ones 4 mm apart across the array.
    Thesis §4.5.6 / docs/validation.md's Ghosts: the stagger's ghost of a target at (3.5°, 1°)
    lies at −3.4°, tan(k δ sin φ) = −24.4 dB below it; the grating lobe of one at −7° at +7°."""
    lam = 1530.0 / 420375.0
    x = -0.0562 + 0.015 * np.arange(8)
    y = np.where(np.arange(8) % 2 == 0, -0.010, -0.014)
    (p1, kd), (p2, none) = ghost_geometry(np.stack([x, y, np.zeros(8)], -1), lam)
    assert none is None
    assert np.degrees(np.arcsin(np.sin(np.radians(3.5)) - p1)) == pytest.approx(-3.4, abs=0.1)   # validation.md: -3.42°
    assert 20 * np.log10(abs(np.tan(kd * np.sin(np.radians(1.0))))) == pytest.approx(-24.4, abs=0.2)
    assert np.degrees(np.arcsin(np.sin(np.radians(-7.0)) + p2)) == pytest.approx(7.0, abs=0.1)   # the rule looks within half a cell, 1.2°
    # a plain (unstaggered) subarray: the grating lobe only
    plain = ghost_geometry(np.stack([x, np.zeros(8), np.zeros(8)], -1), lam)
    assert len(plain) == 1 and plain[0][1] is None and plain[0][0] == pytest.approx(p2)
    assert ghost_geometry(np.zeros((1, 3)), lam) == []


def test_ghost_rule_follows_the_predicted_level():
    """A detection at a stronger one's stagger-ghost azimuth and range is its ghost when no more
    than ghost_db above the level predicted from that one's elevation; a brighter one is a fish."""
    lam, dr, daz = 1490.0 / 420375.0, 0.067, np.radians(2.4)
    period, kd = lam / 0.03, 2 * np.pi / lam * 0.002
    el_strong = np.radians(-1.9)                       # beside the fan: a ghost ~ -19 dB
    level_db = 20 * np.log10(abs(np.tan(kd * np.sin(el_strong))))
    az_g = np.arcsin(np.sin(np.radians(3.47)) - period)
    for below_db, ghost in ((level_db - 2, True), (level_db + 3, True), (level_db + 12, False)):
        side = psf_sidelobes([0, 0], [18.66, 18.66], [np.radians(3.47), az_g], [1.0, 10 ** (below_db / 20)],
                             range_resolution_m=dr, azimuth_resolution_rad=daz, pulse_range_m=5.2,
                             sidelobe_db=30.0, elevation_rad=[el_strong, 0.0],
                             ghosts=[(period, kd), (2 * period, None)], ghost_db=6.0)
        assert side.tolist() == [False, ghost], below_db
    # the same pair a metre apart in range: not a ghost
    side = psf_sidelobes([0, 0], [18.66, 19.66], [np.radians(3.47), az_g], [1.0, 10 ** ((level_db - 2) / 20)],
                         range_resolution_m=dr, azimuth_resolution_rad=daz, pulse_range_m=5.2,
                         sidelobe_db=30.0, elevation_rad=[el_strong, 0.0],
                         ghosts=[(period, kd)], ghost_db=6.0)
    assert not side.any()


def test_sidelobe_db_is_validated_in_one_line():
    with pytest.raises(ConfigError) as e:
        from processing.base.config import validate_file
        validate_file(ProcessingSettings, {"count": {"sidelobe_db": -3}}, file="run.yaml")
    msg = str(e.value)
    assert "count.sidelobe_db" in msg and "\n" not in msg.strip()
