"""Element-level directivity: closed forms, near-field convergence, hard angles."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import diric

from acoustics import ElementArray, array_pattern, array_response, element_directivity
from acoustics.sonar.arrays import abacus_receiver, abacus_transmitter
from acoustics.sonar.directivity import unit_vector

from .conftest import K_RAD_M


def _line(n, pitch, w, h, axis="x"):
    s = (np.arange(n) - (n - 1) / 2) * pitch
    c = np.zeros((n, 3))
    c[:, 0 if axis == "x" else 1] = s
    return ElementArray(c, w, h, 0.0, 1.0, "line")


@pytest.mark.parametrize("n,pitch", [(16, 0.015), (8, 0.015), (5, 0.0018), (1, 0.01)])
def test_uniform_line_equals_dirichlet_times_sinc(n, pitch):
    """Far-field pattern of a uniform line = element sinc x Dirichlet kernel, to 1e-9."""
    w, h = 0.012, 0.020
    arr = _line(n, pitch, w, h)
    th = np.radians(np.linspace(-90, 90, 7201))
    e = array_pattern(arr, th, 0.0, wavenumber_rad_m=K_RAD_M)
    u = np.sin(th)
    dirichlet = diric(K_RAD_M * pitch * u, n)  # sin(nψ/2) / (n sin(ψ/2)), limits included
    element = np.sinc(K_RAD_M * w / 2 * u / np.pi)
    np.testing.assert_allclose(e, element * dirichlet, rtol=0, atol=1e-9)


def test_elevation_line_equals_closed_form():
    """A line along y in the elevation plane: sinc(k h/2 sin φ) x Dirichlet, to 1e-9."""
    n, pitch, w, h = 16, 0.012, 0.020, 0.012
    arr = _line(n, pitch, w, h, axis="y")
    ph = np.radians(np.linspace(-89.9, 89.9, 3001))
    e = array_pattern(arr, 0.0, ph, wavenumber_rad_m=K_RAD_M)
    u = np.sin(ph)
    d = diric(K_RAD_M * pitch * u, n)
    np.testing.assert_allclose(e, np.sinc(K_RAD_M * h / 2 * u / np.pi) * d, atol=1e-9)


def test_broadside_is_exactly_one():
    """sinc(0): on axis every element and the ganged array give exactly 1."""
    tx = abacus_transmitter("abacus")
    one = element_directivity(_line(1, 1, 0.02, 0.012), [[0, 0, 5.0]], wavenumber_rad_m=K_RAD_M)
    assert one[0, 0] == 1.0
    e = array_pattern(tx, 0.0, 0.0, wavenumber_rad_m=K_RAD_M)
    assert abs(e - 1.0) < 1e-12


def test_endfire_and_behind_the_baffle():
    """Endfire is finite (sinc(kw/2)); behind the element plane a baffled piston is silent."""
    w = 0.012
    el = _line(1, 1, w, 0.02)
    e90 = array_pattern(el, np.pi / 2, 0.0, wavenumber_rad_m=K_RAD_M)
    assert np.isclose(e90, np.sinc(K_RAD_M * w / 2 / np.pi), atol=1e-12)
    behind = element_directivity(el, [[0.0, 0.0, -1.0]], wavenumber_rad_m=K_RAD_M)
    assert behind[0, 0] == 0.0
    open_back = element_directivity(el, [[0.0, 0.0, -1.0]], wavenumber_rad_m=K_RAD_M, baffle=False)
    assert open_back[0, 0] == 1.0


def test_field_point_on_an_element_is_finite():
    el = _line(1, 1, 0.02, 0.012)
    for fid in ("far_field", "huygens"):
        d = element_directivity(el, [[0.0, 0.0, 0.0]], wavenumber_rad_m=K_RAD_M, fidelity=fid)
        assert np.all(np.isfinite(d))


def _element_error(array, r, subdivisions):
    """max |huygens - far_field| over the front half-space cut at distance r (both exact paths)."""
    th = np.radians(np.linspace(-60, 60, 241))
    pts = unit_vector(th, 0.0) * r
    hu = element_directivity(array, pts, wavenumber_rad_m=K_RAD_M, fidelity="huygens",
                             subdivisions=subdivisions)
    ff = element_directivity(array, pts, wavenumber_rad_m=K_RAD_M, fidelity="far_field")
    return np.abs(hu - ff).max()


def test_huygens_converges_to_far_field_with_distance():
    """The element-level near-field term is the Fresnel phase k w²/(8r): error ∝ 1/r.

    Between 1 m and 100 m the error must fall by 100x within a factor 2 (1/r law), and at
    100 m it must be below k w²/(8r) = 1.1e-3 for the 0.020 m element."""
    el = _line(1, 1, 0.020, 0.012)
    errs = {r: _element_error(el, r, (16, 16)) for r in (0.05, 0.1, 1.0, 10.0, 100.0)}
    rs = sorted(errs)
    assert all(errs[a] > errs[b] for a, b in zip(rs, rs[1:])), errs
    ratio = errs[1.0] / errs[100.0]
    assert 50 < ratio < 200, errs
    assert errs[100.0] < K_RAD_M * 0.020**2 / (8 * 100.0)


def test_huygens_array_tends_to_plane_wave_pattern():
    """Far away, the huygens array response equals the plane-wave pattern (1e-3 at 5 km)."""
    rx = abacus_receiver("abacus")["A"]
    th = np.radians(np.linspace(-20, 20, 81))
    far = array_pattern(rx, th, 0.0, wavenumber_rad_m=K_RAD_M)
    at = array_pattern(rx, th, 0.0, wavenumber_rad_m=K_RAD_M, fidelity="huygens", distance_m=5000.0,
                       subdivisions=(3, 3))
    # array-level Fresnel phase k L²/(8r) with L = 0.24 m is 2.5e-3 rad at 5 km
    assert np.abs(np.abs(at) - np.abs(far)).max() < 3e-3


def test_array_response_reference_and_spreading():
    """E(P) is referenced to the phase centre: a single element at the origin gives D(P)."""
    el = _line(1, 1, 0.02, 0.012)
    pts = np.array([[0.3, 0.1, 5.0], [1.0, -2.0, 10.0]])
    e = array_response(el, pts, wavenumber_rad_m=K_RAD_M)
    d = element_directivity(el, pts, wavenumber_rad_m=K_RAD_M)[:, 0]
    np.testing.assert_allclose(e, d, atol=1e-15)


angles = st.one_of(st.sampled_from([-90.0, -89.999999, -45.0, 0.0, 1e-12, 45.0, 89.999999, 90.0]),
                   st.floats(-90.0, 90.0, allow_nan=False))


@settings(max_examples=200, deadline=None)
@given(theta=angles, phi=angles)
def test_far_field_pattern_is_bounded_and_finite(theta, phi):
    """At any direction, including endfire and the poles, |E| <= 1 and finite."""
    for arr in (abacus_transmitter("abacus"), abacus_receiver("abacus")["B"]):
        e = array_pattern(arr, np.radians(theta), np.radians(phi), wavenumber_rad_m=K_RAD_M)
        assert np.isfinite(e) and abs(e) <= 1 + 1e-12


@settings(max_examples=100, deadline=None)
@given(theta=angles, phi=angles, r_elements=st.floats(1.0, 1e4))
def test_huygens_is_finite_at_hard_angles(theta, phi, r_elements):
    """Huygens directivity at any direction and any distance >= one element size."""
    el = _line(1, 1, 0.02, 0.012)
    r = r_elements * 0.02
    p = unit_vector(np.radians(theta), np.radians(phi)) * r
    d = element_directivity(el, p[None], wavenumber_rad_m=K_RAD_M, fidelity="huygens",
                            subdivisions=(4, 4))
    assert np.all(np.isfinite(d))
    # each sub-piston's pattern is <= 1 and its spreading ratio R_c/R_s <= r/(r - diag/2)
    diag = np.hypot(0.02, 0.012)
    assert np.abs(d).max() <= r / (r - diag / 2) + 1e-12
    e = array_pattern(el, np.radians(theta), np.radians(phi), wavenumber_rad_m=K_RAD_M,
                      fidelity="huygens", distance_m=r)
    assert np.isfinite(e)


def test_bad_fidelity_is_a_clear_error():
    el = _line(1, 1, 0.02, 0.012)
    with pytest.raises(ValueError, match="fidelity must be one of"):
        element_directivity(el, [[0, 0, 1.0]], wavenumber_rad_m=K_RAD_M, fidelity="exactish")
    with pytest.raises(ValueError, match="subdivisions"):
        element_directivity(el, [[0, 0, 1.0]], wavenumber_rad_m=K_RAD_M, fidelity="huygens",
                            subdivisions=(0, 2))
    with pytest.raises(ValueError, match="distance_m"):
        array_pattern(el, 0.0, 0.0, wavenumber_rad_m=K_RAD_M, distance_m=-1.0)
