"""A moving sea surface: a wind sea from a wave spectrum, or a swell of a few sinusoids.

Linear (Airy) waves: the elevation η(x, y, t) = Σ_k a_k cos(k·x − ω_k t + ϕ_k) over a grid of
wavenumbers, each travelling at its own speed by the dispersion relation of gravity waves on
water of depth d, ω² = g k tanh(k d) (deep water: ω² = g k). The surface is a height field in the
world frame (z down): z = mean_level − η.

Spectra (Stewart, *Introduction to Physical Oceanography*, 2008, §16.5):

``pierson_moskowitz``  the fully developed sea of wind U₁₉.₅ (m/s at 19.5 m, taken as 1.026 U₁₀):
                       S(ω) = α g² ω⁻⁵ exp(−0.74 (g / (U₁₉.₅ ω))⁴), α = 8.1·10⁻³;
                       H_s = 4 √(∫S dω) = 0.21 U₁₉.₅² / g (2.25 m at U₁₀ = 10 m/s).
``jonswap``            the fetch-limited sea (Hasselmann et al. 1973): α = 0.076 (U₁₀²/(F g))^0.22,
                       ω_p = 22 (g²/(U₁₀ F))^⅓, peak enhancement γ = 3.3,
                       σ = 0.07 (ω ≤ ω_p), 0.09 (ω > ω_p).

Directional spreading D(θ) ∝ cos^{2s}((θ − θ_w)/2) (Longuet-Higgins et al. 1963), kept to waves
travelling with the wind (|θ − θ_w| < 90°, renormalised): with no two components opposite, the
mean square of the sampled surface is exactly Σ a²/2 (Parseval), which the tests check.

The grid's spacing is the mesh resolution, the accuracy knob: waves shorter than two grid steps
(k > π/Δ) are not resolved, nor are waves longer than the grid (the surface is periodic over it),
and their share of the spectrum's variance is reported (``unresolved_variance_fraction``); what is shorter than the
mesh belongs to the diffuse scattering law of the surface, not to its specular geometry.
The amplitudes are deterministic (√(2 F Δk_x Δk_y)), the phases seeded: the same seed gives the
same sea at every ping time on any worker.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GRAVITY_M_S2", "pierson_moskowitz", "jonswap", "significant_wave_height_m",
           "MovingSurface", "wind_sea", "swell", "surface_of"]

GRAVITY_M_S2 = 9.81


def pierson_moskowitz(omega_rad_s, wind_speed_m_s: float):
    """Pierson–Moskowitz frequency spectrum S(ω) (m² s) of a fully developed sea.

    Parameters
    ----------
    omega_rad_s : array_like
        Angular frequency ω (rad/s), > 0.
    wind_speed_m_s : float
        Wind speed at 10 m, U₁₀ (m/s).
    """
    w = np.asarray(omega_rad_s, float)
    u195 = 1.026 * wind_speed_m_s
    g = GRAVITY_M_S2
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        s = 8.1e-3 * g**2 / w**5 * np.exp(-0.74 * (g / (u195 * w)) ** 4)
    return np.where(w > 0, np.nan_to_num(s, nan=0.0, posinf=0.0), 0.0)


def jonswap(omega_rad_s, wind_speed_m_s: float, fetch_m: float, gamma: float = 3.3):
    """JONSWAP frequency spectrum S(ω) (m² s) of a fetch-limited sea.

    Parameters
    ----------
    omega_rad_s : array_like
        ω (rad/s), > 0.
    wind_speed_m_s : float
        U₁₀ (m/s).
    fetch_m : float
        Fetch F (m).
    gamma : float
        Peak enhancement factor.
    """
    w = np.asarray(omega_rad_s, float)
    g, u, f = GRAVITY_M_S2, wind_speed_m_s, fetch_m
    alpha = 0.076 * (u * u / (f * g)) ** 0.22
    wp = 22.0 * (g * g / (u * f)) ** (1.0 / 3.0)
    sigma = np.where(w <= wp, 0.07, 0.09)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        r = np.exp(-((w - wp) ** 2) / (2 * sigma**2 * wp**2))
        s = alpha * g**2 / w**5 * np.exp(-1.25 * (wp / w) ** 4) * gamma**r
    return np.where(w > 0, np.nan_to_num(s, nan=0.0, posinf=0.0), 0.0)


def significant_wave_height_m(spectrum, omega_max_rad_s: float = 20.0, n: int = 200_000):
    """H_s = 4 √(∫ S dω) of a frequency spectrum ``spectrum(ω)`` (m)."""
    w = np.linspace(1e-4, omega_max_rad_s, n)
    return 4.0 * np.sqrt(np.trapezoid(spectrum(w), w))


def _omega(k, depth_m):
    g = GRAVITY_M_S2
    if depth_m is None:
        return np.sqrt(g * k)
    return np.sqrt(g * k * np.tanh(k * depth_m))


@dataclass(frozen=True)
class MovingSurface:
    """A sum of travelling sinusoids sampled on a regular grid (world frame, z down).

    Attributes
    ----------
    x_m, y_m : ndarray, shape (nx,), (ny,)
        Grid lines (m).
    k_m : ndarray, shape (c, 2)
        Wavenumber vectors (rad/m).
    amplitude_m : ndarray, shape (c,)
    phase_rad : ndarray, shape (c,)
    omega_rad_s : ndarray, shape (c,)
        From the dispersion relation.
    mean_level_m : float
        z of the still surface (m, world frame, z down).
    unresolved_variance_fraction : float
        Share of the spectrum's variance in waves the grid does not hold (shorter than two
        steps or longer than the grid).
    """

    x_m: np.ndarray
    y_m: np.ndarray
    k_m: np.ndarray
    amplitude_m: np.ndarray
    phase_rad: np.ndarray
    omega_rad_s: np.ndarray
    mean_level_m: float = 0.0
    unresolved_variance_fraction: float = 0.0
    lattice: tuple | None = None
    """(m_x (c,), m_y (c,)) when every k is 2π m / L on the grid's period: the grid is then one
    inverse FFT."""

    def elevation(self, x_m, y_m, time_s: float):
        """η (m, up) and its slopes ∂η/∂x, ∂η/∂y at points (x, y) and time t (arrays alike)."""
        x = np.asarray(x_m, float)
        y = np.asarray(y_m, float)
        eta = np.zeros(np.broadcast(x, y).shape)
        ex = np.zeros_like(eta)
        ey = np.zeros_like(eta)
        # chunks over components keep the (points x components) block small
        for lo in range(0, self.amplitude_m.size, 256):
            sl = slice(lo, lo + 256)
            kx, ky = self.k_m[sl, 0], self.k_m[sl, 1]
            arg = (x[..., None] * kx + y[..., None] * ky - self.omega_rad_s[sl] * time_s
                   + self.phase_rad[sl])
            a = self.amplitude_m[sl]
            eta += np.cos(arg) @ a
            s = np.sin(arg) * a
            ex -= s @ kx
            ey -= s @ ky
        return eta, ex, ey

    @property
    def reach_m(self) -> float:
        """The most the surface can rise above or fall below its mean level, Σ|a| (m)."""
        return float(np.sum(np.abs(self.amplitude_m)))

    def elevation_series(self, x_m, y_m, times_s):
        """η (m, up) at fixed points over many times, shape (n, T) for n points and T times.

        Each point's spatial phases are taken once, and every block of times is one matrix
        product, η = Re[(a e^{i(k·x + ϕ)}) · e^{−iωt}], so that every ping of a long run costs
        little (the scene check's per-ping test that the sea stays above the sonar and targets).
        """
        x = np.asarray(x_m, float).reshape(-1)
        y = np.asarray(y_m, float).reshape(-1)
        t = np.asarray(times_s, float).reshape(-1)
        out = np.zeros((x.size, t.size))
        c = self.amplitude_m.size
        if not (x.size and t.size and c):
            return out
        spatial = self.amplitude_m * np.exp(1j * (np.outer(x, self.k_m[:, 0])
                                                  + np.outer(y, self.k_m[:, 1]) + self.phase_rad))
        block = max(1, (1 << 21) // c)
        for lo in range(0, t.size, block):
            temporal = np.exp(-1j * np.outer(self.omega_rad_s, t[lo:lo + block]))
            out[:, lo:lo + block] = (spatial @ temporal).real
        return out

    def elevation_at(self, x_m, y_m, time_s):
        """η (m, up) at points that move: one value per (x, y, t), the three broadcast together
        (e.g. a target's position at each ping and that ping's time)."""
        x, y, t = np.broadcast_arrays(*(np.asarray(v, float) for v in (x_m, y_m, time_s)))
        shape = x.shape
        x, y, t = (v.reshape(-1) for v in (x, y, t))
        out = np.zeros(x.size)
        c = max(self.amplitude_m.size, 1)
        block = max(1, (1 << 21) // c)
        for lo in range(0, x.size, block):
            sl = slice(lo, lo + block)
            arg = (np.outer(x[sl], self.k_m[:, 0]) + np.outer(y[sl], self.k_m[:, 1])
                   - np.outer(t[sl], self.omega_rad_s) + self.phase_rad)
            out[sl] = np.cos(arg) @ self.amplitude_m
        return out.reshape(shape)

    def height(self, x_m, y_m, time_s: float):
        """The surface z(x, y) (m, world frame, z down) and its derivatives at time t.

        Returns
        -------
        tuple of ndarray
            z, z_x, z_y, z_xx, z_xy, z_yy, each shaped like ``x_m``.
        """
        x = np.asarray(x_m, float)
        y = np.asarray(y_m, float)
        shape = np.broadcast(x, y).shape
        out = [np.zeros(shape) for _ in range(6)]
        kx, ky, a = self.k_m[:, 0], self.k_m[:, 1], self.amplitude_m
        for lo in range(0, a.size, 256):
            sl = slice(lo, lo + 256)
            arg = (x[..., None] * kx[sl] + y[..., None] * ky[sl] - self.omega_rad_s[sl] * time_s
                   + self.phase_rad[sl])
            c, s_ = np.cos(arg) * a[sl], np.sin(arg) * a[sl]
            # z = L − η: z_x = a k_x sin, z_xx = a k_x² cos, ...
            out[0] -= c.sum(-1)
            out[1] += s_ @ kx[sl]
            out[2] += s_ @ ky[sl]
            out[3] += c @ (kx[sl] * kx[sl])
            out[4] += c @ (kx[sl] * ky[sl])
            out[5] += c @ (ky[sl] * ky[sl])
        out[0] += self.mean_level_m
        return tuple(out)

    def vertical_velocity(self, x_m, y_m, time_s: float):
        """∂z/∂t (m/s, world frame, z down: positive when the surface sinks) at fixed (x, y)."""
        x = np.asarray(x_m, float)
        y = np.asarray(y_m, float)
        out = np.zeros(np.broadcast(x, y).shape)
        for lo in range(0, self.amplitude_m.size, 256):
            sl = slice(lo, lo + 256)
            arg = (x[..., None] * self.k_m[sl, 0] + y[..., None] * self.k_m[sl, 1]
                   - self.omega_rad_s[sl] * time_s + self.phase_rad[sl])
            # η = Σ a cos(arg): ∂η/∂t = Σ a ω sin(arg); z = L − η
            out -= np.sin(arg) @ (self.amplitude_m[sl] * self.omega_rad_s[sl])
        return out

    def grid(self, time_s: float):
        """Vertices (ny·nx, 3) and unit normals (ny·nx, 3) pointing up (−z) at time t; the
        vertex order of :func:`acoustics.paths.meshes._grid_mesh`."""
        xx, yy = np.meshgrid(self.x_m, self.y_m)
        if self.lattice is None:
            eta, ex, ey = self.elevation(xx, yy, time_s)
        else:
            eta, ex, ey = self._grid_fft(time_s)
        v = np.column_stack([xx.ravel(), yy.ravel(), (self.mean_level_m - eta).ravel()])
        # z = L − η(x, y): the upward (−z) normal is (−∂η/∂x, −∂η/∂y, −1)/|.| in (x, y, z)
        n = np.column_stack([-ex.ravel(), -ey.ravel(), -np.ones(ex.size)])
        n /= np.linalg.norm(n, axis=1)[:, None]
        return v, n

    def _grid_fft(self, time_s):
        """η and its slopes on the grid by one inverse FFT each (the grid spans one period)."""
        mx, my = self.lattice
        nx, ny = self.x_m.size - 1, self.y_m.size - 1
        c = self.amplitude_m * np.exp(1j * (self.phase_rad - self.omega_rad_s * time_s
                                            + self.k_m[:, 0] * self.x_m[0]
                                            + self.k_m[:, 1] * self.y_m[0]))
        out = []
        for factor in (1.0, 1j * self.k_m[:, 0], 1j * self.k_m[:, 1]):
            spec = np.zeros((ny, nx), complex)
            np.add.at(spec, (my % ny, mx % nx), c * factor)
            field = np.real(np.fft.ifft2(spec)) * (nx * ny)
            # the last grid line repeats the first: the surface is periodic over the grid
            out.append(np.pad(field, ((0, 1), (0, 1)), mode="wrap"))
        return out

    @property
    def variance_m2(self) -> float:
        """Mean square elevation of the resolved surface, Σ a²/2 (m²)."""
        return float(np.sum(self.amplitude_m**2) / 2)


def _grid_lines(center_m, size_m, resolution_m, limit=4_000_000):
    nx = int(np.ceil(size_m[0] / resolution_m)) + 1
    ny = int(np.ceil(size_m[1] / resolution_m)) + 1
    if nx * ny > limit:
        raise ValueError(f"a sea surface of {nx} x {ny} vertices is too fine (limit "
                         f"{limit:,}): raise resolution_m or shrink size_m")
    x = center_m[0] + np.linspace(-size_m[0] / 2, size_m[0] / 2, nx)
    y = center_m[1] + np.linspace(-size_m[1] / 2, size_m[1] / 2, ny)
    return x, y


def wind_sea(*, wind_speed_m_s: float, direction_deg: float = 0.0, fetch_m: float | None = None,
             spreading: float = 10.0, center_m=(0.0, 0.0), size_m=(60.0, 60.0),
             resolution_m: float = 0.25, depth_m: float | None = None, mean_level_m: float = 0.0,
             seed: int = 0) -> MovingSurface:
    """A wind sea of random phases with the spectrum of the wind (see the module notes).

    Parameters
    ----------
    wind_speed_m_s : float
        U₁₀ (m/s).
    direction_deg : float
        Direction the waves travel to, from the world x axis towards y (degrees).
    fetch_m : float, optional
        JONSWAP with this fetch; None: Pierson–Moskowitz (fully developed).
    spreading : float
        s of cos^{2s}(Δθ/2).
    center_m, size_m : (float, float)
        Horizontal centre and extent of the grid (m).
    resolution_m : float
        Grid step (m): the mesh resolution.
    depth_m : float, optional
        Water depth for the dispersion relation; None: deep water.
    mean_level_m : float
        z of the still surface (world frame, z down).
    seed : int
        Phases.
    """
    x, y = _grid_lines(center_m, size_m, resolution_m)
    # wavenumbers periodic over the grid's extent (k = 2π m / L), below the grid's Nyquist;
    # the Nyquist lines themselves are left out: a mode there aliases onto its mirror
    lx, ly = x[-1] - x[0], y[-1] - y[0]
    nx, ny = x.size - 1, y.size - 1
    mx = np.arange(-(nx // 2) + 1, nx // 2 + (nx % 2)) if nx > 1 else np.zeros(1, int)
    my = np.arange(-(ny // 2) + 1, ny // 2 + (ny % 2)) if ny > 1 else np.zeros(1, int)
    dkx, dky = 2 * np.pi / lx, 2 * np.pi / ly
    MX, MY = np.meshgrid(mx, my)
    KX, KY = MX * dkx, MY * dky
    k = np.hypot(KX, KY)
    th0 = np.radians(direction_deg)
    dirn = np.array([np.cos(th0), np.sin(th0)])
    along = KX * dirn[0] + KY * dirn[1]
    keep = (along > 0) & (k > 0) & (k < np.pi / (lx / nx) if nx else True)
    kk, theta = k[keep], np.arctan2(KY[keep], KX[keep])

    def spectrum(w):
        if fetch_m is None:
            return pierson_moskowitz(w, wind_speed_m_s)
        return jonswap(w, wind_speed_m_s, fetch_m)

    # direction density on |Δθ| < 90°, normalised there
    dth = np.angle(np.exp(1j * (theta - th0)))
    grid_th = np.linspace(-np.pi / 2, np.pi / 2, 4001)
    norm = np.trapezoid(np.cos(grid_th / 2) ** (2 * spreading), grid_th)
    D = np.cos(dth / 2) ** (2 * spreading) / norm
    w = _omega(kk, depth_m)
    # F(k, θ) = S(ω) dω/dk D(θ); Cartesian density F/k
    g = GRAVITY_M_S2
    if depth_m is None:
        dw_dk = g / (2 * w)
    else:
        t = np.tanh(kk * depth_m)
        dw_dk = g * (t + kk * depth_m * (1 - t * t)) / (2 * w)
    F = spectrum(w) * dw_dk * D / kk
    amp = np.sqrt(2 * F * dkx * dky)
    rng = np.random.default_rng([int(seed), 0x5EA])
    phase = rng.uniform(-np.pi, np.pi, amp.size)
    # variance of the whole spectrum in the same direction window vs what the grid holds
    wfine = np.linspace(1e-3, 60.0, 200_000)
    total = np.trapezoid(spectrum(wfine), wfine)
    resolved = float(np.sum(amp**2) / 2)
    unresolved = float(max(0.0, 1.0 - resolved / total)) if total > 0 else 0.0
    big = amp > 1e-6 * max(amp.max(initial=0.0), 1e-300)    # components that matter
    return MovingSurface(x, y, np.column_stack([KX[keep], KY[keep]])[big], amp[big], phase[big],
                         w[big], float(mean_level_m), unresolved,
                         (MX[keep][big], MY[keep][big]))


def swell(*, components, center_m=(0.0, 0.0), size_m=(60.0, 60.0), resolution_m: float = 0.25,
          depth_m: float | None = None, mean_level_m: float = 0.0) -> MovingSurface:
    """A swell: a few long sinusoids, each (amplitude_m, wavelength_m, direction_deg, phase_deg).

    Parameters
    ----------
    components : sequence of (float, float, float, float)
        Amplitude (m), wavelength (m), direction of travel from x towards y (degrees), phase at
        t = 0 and x = y = 0 (degrees).
    center_m, size_m, resolution_m, depth_m, mean_level_m
        As :func:`wind_sea`.
    """
    x, y = _grid_lines(center_m, size_m, resolution_m)
    c = np.asarray(components, float).reshape(-1, 4)
    k = 2 * np.pi / c[:, 1]
    th = np.radians(c[:, 2])
    kv = np.column_stack([k * np.cos(th), k * np.sin(th)])
    return MovingSurface(x, y, kv, c[:, 0], np.radians(c[:, 3]), _omega(k, depth_m),
                         float(mean_level_m), 0.0)


def surface_of(spec, seed: int = 0) -> MovingSurface:
    """The surface of a scene's ``wind_sea`` or ``swell`` shape (before its transform), ``seed``
    the scene's: the sea :func:`acoustics.paths.meshes.moving_surface` builds for the simulation
    (tests/test_scene_bounds.py checks they agree), for the scene check, which may not import the
    mesh module (it imports the scene package)."""
    common = dict(center_m=spec.center_m, size_m=spec.size_m, resolution_m=spec.resolution_m,
                  depth_m=spec.water_depth_m, mean_level_m=spec.mean_level_m)
    if spec.shape == "wind_sea":
        return wind_sea(wind_speed_m_s=spec.wind_speed_m_s, direction_deg=spec.direction_deg,
                        fetch_m=None if spec.fetch_km is None else 1e3 * spec.fetch_km,
                        spreading=spec.spreading, seed=seed + spec.seed, **common)
    return swell(components=[(w.amplitude_m, w.wavelength_m, w.direction_deg, w.phase_deg)
                             for w in spec.waves], **common)
