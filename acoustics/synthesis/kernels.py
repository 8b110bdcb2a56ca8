"""Scalar maths for the compiled hot loops, accurate to ~1e-15 and cheap.

libm's sin, cos and exp are correct but slow inside a loop over millions of (scatterer,
element) pairs, mostly because the carrier phase k·(r1 + r2) is ~10⁵ rad and needs a costly
argument reduction. Here the phase is reduced *in cycles* first — frac((r1 + r2)/λ), exact to
~1e-12 cycle in float64 — so only small arguments reach the polynomials:

- :func:`sincos` : |x| ≲ 10³ rad, quadrant reduction by π/2 and the fdlibm minimax kernels
  (__kernel_sin / __kernel_cos, error < 1 ulp on [−π/4, π/4]);
- :func:`sine` : sin x alone, |x| ≲ 10³ rad, reduced by π to [−π/2, π/2] and one odd
  polynomial (about half the work of :func:`sincos`: one polynomial and a sign, where the
  quadrant of :func:`sincos` needs both polynomials and selects between them);
- :func:`cis_cycles` : e^{j2πc} for any c, reduced in quarter cycles (exact);
- :func:`sin_over` : sin(a)/a, exactly 1 at a = 0;
- :func:`exp_small` : e^x for |x| <= 0.05 (degree-8 Taylor, relative error < 1e-16), used for
  the absorption difference between the two legs of a path.

tests/test_kernels_targets.py checks each against numpy over its whole domain. They are written
without data-dependent branches (quadrants by selects) so that the loops calling them vectorise;
callers must compile with ``error_model="numpy"`` (numba's default Python error model puts a
zero check on every division, which stops LLVM from vectorising).
"""
from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["sincos", "sine", "cis_cycles", "sin_over", "exp_small", "EXP_SMALL_LIMIT"]

_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
# sin r = r + r z (T1 + z (T2 + ... + z T8)), z = r², |r| <= π/2: a Chebyshev fit of
# (sin r − r) / r³ in z (mpmath.chebyfit, 40 digits), whose error is at most 1.3e-18 in sin r
# (the Taylor series would need two more terms for that)
_T1, _T2, _T3 = -0.16666666666666666, 0.008333333333333316, -0.00019841269841254974
_T4, _T5, _T6 = 2.7557319219163234e-06, -2.5052107616996182e-08, 1.6058977312464087e-10
_T7, _T8 = -7.643970296798572e-13, 2.7314447669863995e-15
_INV_PI = 1 / np.pi
_PI_LO = 1.2246467991473532e-16  # π − float64(π)
_PIO2 = np.pi / 2
_TWO_52 = 2.0 ** 52
_TWO_OVER_PI = 2 / np.pi
_TWO_PI = 2 * np.pi
#: exp_small is exact to double precision for |x| below this
EXP_SMALL_LIMIT = 0.05


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _quadrant(r, q):
    """(sin, cos) of r + q π/2 for |r| <= π/4 and q an integer (as a float): the polynomials
    of r and the quadrant q mod 4, by selects, not branches (the carrier's quadrant is random,
    a branch mispredicts)."""
    z = r * r
    s = r + r * z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    c = 1.0 - 0.5 * z + z * z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    qi = int(q) & 3
    a = c if qi & 1 else s
    b = s if qi & 1 else c
    return (-a if qi & 2 else a), (-b if (qi + 1) & 2 else b)


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def sincos(x):
    """(sin x, cos x) for |x| up to ~1e3 rad; absolute error <= 2e-16 (4 + |x|)."""
    q = np.floor(x * _TWO_OVER_PI + 0.5)
    return _quadrant(x - q * _PIO2, q)


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def sine(x):
    """sin x for |x| up to ~1e3 rad; absolute error <= 2e-16 (4 + |x|)."""
    q = np.floor(x * _INV_PI + 0.5)
    r = (x - q * np.pi) - q * _PI_LO
    z = r * r
    s = r + r * z * (_T1 + z * (_T2 + z * (_T3 + z * (_T4 + z * (_T5 + z * (_T6 + z * (
        _T7 + z * _T8)))))))
    # sin(r + qπ) = (−1)^q sin r, by a select (no branch: vectorises)
    return -s if int(q) & 1 else s


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def cis_cycles(cycles):
    """(sin 2πc, cos 2πc) for any float64 c, reduced in quarter cycles: 4c = q + f with q an
    integer and |f| <= 1/2, both exact in float64, so only the polynomials' argument (π/2) f
    is rounded (:func:`sincos`'s kernels and quadrant selects, without its reduction)."""
    c4 = 4.0 * cycles
    q = np.floor(c4 + 0.5)
    # from 2^52 on c4 is an integer, and c4 + 1/2 a tie that rounds an odd c4 up: |c4 − q| = 1,
    # outside the polynomials' range (2.5e-10 off at c = 2^50 + 1/4); q = c4 there (a select)
    q = c4 if abs(c4) >= _TWO_52 else q
    return _quadrant((c4 - q) * _PIO2, q)


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def sin_over(a):
    """sin(a)/a with the removable singularity filled (1 at a = 0)."""
    if abs(a) < 1e-5:
        return 1.0 - a * a * (1.0 / 6.0)
    s, _ = sincos(a)
    return s / a


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def exp_small(x):
    """e^x for |x| <= EXP_SMALL_LIMIT."""
    return 1.0 + x * (1.0 + x * (0.5 + x * (1.0 / 6 + x * (1.0 / 24 + x * (1.0 / 120 + x * (
        1.0 / 720 + x * (1.0 / 5040 + x * (1.0 / 40320))))))))
