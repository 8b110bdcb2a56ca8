"""Three physics corrections of the second wave, each against an independent derivation."""
from __future__ import annotations

import numpy as np
import pytest

from acoustics.medium import mackenzie_sound_speed_m_s
from acoustics.paths.scattering import rayleigh_reflection
from acoustics.scene import scene_from_text

M, CR = 1900.0 / 1027.0, 1700.0 / 1500.0        # a sand bottom: density ratio, speed ratio
N = 1.0 / CR
CRITICAL = np.arcsin(N)                            # incidence 61.9° from the normal (grazing 28.1°)


def _boundary_solution(theta):
    """R from the boundary conditions alone, e^{+jωt}, z down into the bottom.

    p continuous: 1 + R = T; normal velocity v_z = −(1/jωρ) ∂p/∂z continuous:
    (k1z/ρ1)(1 − R) = (k2z/ρ2) T. The transmitted wave e^{j(ωt − k2z z)} must not grow with z:
    k2z = k1 √(n² − sin²θ) below critical, −j k1 √(sin²θ − n²) beyond it.
    """
    k1 = 1.0
    k1z = k1 * np.cos(theta)
    d = N**2 - np.sin(theta) ** 2
    k2z = np.where(d >= 0, k1 * np.sqrt(np.abs(d)), -1j * k1 * np.sqrt(np.abs(d)))
    rho1, rho2 = 1.0, M
    out = []
    for a, b in zip(np.atleast_1d(k1z), np.atleast_1d(k2z)):
        A = np.array([[1.0, -1.0], [a / rho1, b / rho2]], complex)   # unknowns R, T
        rhs = np.array([-1.0, a / rho1], complex)
        out.append(np.linalg.solve(A, rhs)[0])
    return np.array(out)


def test_reflection_equals_the_boundary_value_solution_on_both_sides_of_critical():
    theta = np.radians(np.linspace(0.0, 89.5, 180))
    np.testing.assert_allclose(rayleigh_reflection(theta, density_ratio=M, speed_ratio=CR),
                               _boundary_solution(theta), rtol=0, atol=1e-12)


def test_beyond_critical_the_transmitted_wave_decays_and_the_phase_is_positive():
    theta = np.radians(np.linspace(np.degrees(CRITICAL) + 0.5, 89.5, 50))
    r = rayleigh_reflection(theta, density_ratio=M, speed_ratio=CR)
    np.testing.assert_allclose(np.abs(r), 1.0, atol=1e-12)          # total reflection
    # the vertical wavenumber ratio s = k2z/k1 implied by R: Im s < 0, so e^{−j k2z z} decays
    s = M * np.cos(theta) * (1 - r) / (1 + r)
    assert np.all(s.imag < 0)
    expected = 2 * np.arctan(np.sqrt(np.sin(theta) ** 2 - N**2) / (M * np.cos(theta)))
    np.testing.assert_allclose(np.angle(r), expected, atol=1e-12)   # in (0, π), not its negative
    assert np.all(np.angle(r) > 0)


def test_reflection_limits():
    assert rayleigh_reflection(0.0, density_ratio=M, speed_ratio=CR) == pytest.approx(
        (M * CR - 1) / (M * CR + 1), abs=1e-12)                     # (Z2 − Z1)/(Z2 + Z1)
    assert rayleigh_reflection(np.radians(89.999), density_ratio=M, speed_ratio=CR) == pytest.approx(
        -1.0, abs=1e-3)                                               # grazing
    assert np.isfinite(rayleigh_reflection(np.pi / 2, density_ratio=M, speed_ratio=CR))


def test_mackenzie_check_value():
    """Mackenzie (1981), J. Acoust. Soc. Am. 70, 807: c = 1550.744 m/s at 25 °C, 35 ppt, 1000 m."""
    assert float(mackenzie_sound_speed_m_s(25.0, 35.0, 1000.0)) == pytest.approx(1550.744, abs=1e-3)


def test_sound_speed_follows_the_water_unless_given():
    warm = scene_from_text("name: warm\nmedium: {temperature_c: 25, salinity_psu: 38, depth_m: 30}\n")
    expected = float(mackenzie_sound_speed_m_s(25.0, 38.0, 30.0))
    assert warm.medium.sound_speed_m_s == pytest.approx(expected, abs=1e-5)
    assert warm.wavelength_m == pytest.approx(expected / warm.signal.center_frequency_hz)
    assert abs(warm.medium.sound_speed_m_s - 1530.0) > 5      # not the old fixed value
    given = scene_from_text("name: given\nmedium: {temperature_c: 25, sound_speed_m_s: 1500}\n")
    assert given.medium.sound_speed_m_s == 1500.0
    # the resolved scene states the speed, so it round-trips to the same number
    again = scene_from_text(warm.resolved_text())
    assert again.medium.sound_speed_m_s == warm.medium.sound_speed_m_s


def test_density_where_the_targets_are_and_of_the_counting_volume():
    """Fish in a 15–25 m layer, counted in a 13–26 m volume: count / V reads the volume's density
    (a fifth of it empty), count / V_occ the layer's; V_occ from the located ranges must match the
    sector between 15 and 25 m (exact geometry), within the order-statistics error of a few %."""
    import processing
    import acoustics
    from processing.base.counting_volume import counting_volume
    sc = scene_from_text("""name: layer
medium: {sound_speed_m_s: 1530}
targets:
  populations:
    - {kind: uniform_cuboid, frame: world, x_m: [-1.4, 1.4], y_m: [-3.9, 3.9], z_m: [15.0, 25.0],
       count: 100, redraw: true}
pings: {count: 30}
processing:
  detect: {method: fraction_of_peak, fraction: 0.1}
""")
    counted = processing.count(acoustics.simulate(sc))
    c = processing.counts_of(counted)
    vol = counting_volume(tx_beamwidth_az_rad=np.radians(float(counted["Sonar"]["beamwidth_transmit_major"])),
                          tx_beamwidth_el_rad=np.radians(float(counted["Sonar"]["beamwidth_transmit_minor"])),
                          image_range_m=(13.0, 26.0))
    layer_m3 = vol.sector_volume_m3((15.0, 25.0))          # the fish are at 15–25 m (near-vertical)
    ratio = np.nanmean(c["occupied_density_per_m3"].values) / np.nanmean(c["density_per_m3"].values)
    assert ratio == pytest.approx(vol.volume_m3 / layer_m3, rel=0.05)    # 1.255
    r0, r1 = c.attrs["occupied_range_m"]
    assert r0 == pytest.approx(15.0, abs=0.3) and r1 == pytest.approx(25.0, abs=0.4)
    # the volume's density is what it says: counted / V
    np.testing.assert_allclose(c["density_per_m3"].values, c["count_after"].values / vol.volume_m3)


def test_a_school_of_known_density_is_read_where_it_is():
    """An ellipsoidal school of 1 fish/m³ (16 x 16 x 6 m, 17–23 m down) fills the fan between
    17 and 23 m: the density where the targets are reads the school's 1/m³, the volume's density
    reads it diluted by the empty 13–17 and 23–26 m (x 0.47). Tolerance: 3 Poisson standard
    errors of the ~195 fish counted over the run (22 %), plus the 3 % of the 17–23 m sector the
    ellipsoid's curved top and bottom leave empty at the fan's edges."""
    import acoustics
    import processing
    from processing.base.counting_volume import counting_volume
    sc = scene_from_text("""name: school-density
medium: {sound_speed_m_s: 1530}
targets:
  populations:
    - {kind: school, center_m: [0.0, 0.0, 20.0], semi_axes_m: [8.0, 8.0, 3.0], density_per_m3: 1.0,
       nearest_neighbour_m: 0.3, redraw: true}
pings: {count: 30}
processing:
  detect: {method: fraction_of_peak, fraction: 0.1}
""")
    counted = processing.count(acoustics.simulate(sc))
    c = processing.counts_of(counted)
    vol = counting_volume(tx_beamwidth_az_rad=np.radians(float(counted["Sonar"]["beamwidth_transmit_major"])),
                          tx_beamwidth_el_rad=np.radians(float(counted["Sonar"]["beamwidth_transmit_minor"])),
                          image_range_m=(13.0, 26.0))
    expected_n = 1.0 * vol.sector_volume_m3((17.0, 23.0)) * 30
    tol = 3 / np.sqrt(expected_n) + 0.03
    assert np.nanmean(c["occupied_density_per_m3"].values) == pytest.approx(1.0, rel=tol)
    dilution = vol.sector_volume_m3((17.0, 23.0)) / vol.volume_m3
    assert np.mean(c["density_per_m3"].values) == pytest.approx(dilution, rel=tol)
    r0, r1 = c.attrs["occupied_range_m"]
    assert r0 == pytest.approx(17.0, abs=0.3) and r1 == pytest.approx(23.0, abs=0.3)
