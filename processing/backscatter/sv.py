"""Calibrated volume backscattering per image cell: Sv(r, θ), its gridded means (MVBS) and NASC.

Every cell of a calibrated image (processing/backscatter/calibration.py) is inverted with the sonar equation
that :mod:`processing.backscatter.echo_integration` integrates over the counting span,

    s_v(r, θ_b) = (|I|² − N) r² 10^(α r / 5) / (G² L_r Ψ_b)          (m⁻¹),
    Sv = 10 log10 s_v                                                  (dB re 1 m⁻¹),

N the noise power of a cell, L_r = ∫ |h(r)|² dr the range extent of the compressed pulse's
intensity and Ψ_b the beam's two-way equivalent solid angle (for a single-beam echosounder,
L_r Ψ_b is the familiar cτ/2 · ψ: MacLennan & Simmonds, *Fisheries Acoustics*, §2.4; echopype's
``compute_Sv`` uses the same TVG, 20 log r + 2αr). Gridded means are taken in the linear
domain (MVBS, as echopype's ``compute_MVBS`` and Echoview's grids do), and the nautical area
scattering coefficient of a range layer is

    NASC = 4π 1852² ∫ s_v dr            (m² nmi⁻²; MacLennan, Fernandes & Dalen 2002),

integrated along each beam: for a vertical beam it is the NASC of the depth layer; for a beam at
θ from the vertical the depth layer's NASC is NASC · cos θ. Noise subtraction makes a cell's s_v
negative where there is nothing but noise: kept in the linear products (clipping would bias the
means) and NaN in dB, where ``nan_means`` says so.
"""
from __future__ import annotations

import numpy as np

from processing.base.contract import SV_GROUP
from processing.base.dataset import DatasetError

__all__ = ["sv_cells", "sv_db", "mean_volume_backscatter", "nasc", "backscatter", "SV_GROUP",
           "write_mvbs_csv", "write_nasc_csv", "write_cells_csv", "EMPTY_VALUES", "LayerError"]

NMI_M = 1852.0


def sv_cells(magnitude, range_m, *, gain_counts_m: float, absorption_db_per_m: float,
             range_width_m: float, solid_angle_sr, noise_power=0.0) -> np.ndarray:
    """s_v of every image cell.

    Parameters
    ----------
    magnitude : array_like, shape (n_pings, n_range, n_beams)
        |I| of a calibrated image (counts).
    range_m : array_like, shape (n_range,)
    gain_counts_m, absorption_db_per_m : float
        The calibration's G and α (processing.backscatter.calibration.Calibration).
    range_width_m : float
        L_r (m), :func:`processing.backscatter.calibration.range_energy_width_m`.
    solid_angle_sr : array_like, shape (n_beams,)
        Ψ_b (sr), :func:`processing.backscatter.calibration.beam_solid_angle_sr`.
    noise_power : float or array_like, shape (n_pings,)
        Mean noise intensity of a cell (counts²), 2σ² for a Rayleigh σ; 0 without noise.

    Returns
    -------
    ndarray, shape (n_pings, n_range, n_beams)
        s_v (m⁻¹); may be slightly negative in noise-only cells.
    """
    mag = np.asarray(magnitude, float)
    r = np.asarray(range_m, float)
    psi = np.asarray(solid_angle_sr, float)
    scale = (r**2 * 10.0 ** (absorption_db_per_m * r / 5.0))[:, None] / (
        gain_counts_m**2 * range_width_m * psi[None, :])
    n = np.asarray(noise_power, float).reshape(-1, 1, 1) if np.ndim(noise_power) else float(noise_power)
    return (mag**2 - n) * scale[None]


def sv_db(s_v) -> np.ndarray:
    """Sv = 10 log10 s_v (dB re 1 m⁻¹), same shape; NaN where s_v ≤ 0 (noise only)."""
    s = np.asarray(s_v, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s > 0, 10.0 * np.log10(np.where(s > 0, s, 1.0)), np.nan)


def mean_volume_backscatter(s_v, range_m, *, range_bin_m: float, ping_bin: int):
    """MVBS: s_v averaged (linearly) over bins of range and of consecutive pings, per beam.

    Parameters
    ----------
    s_v : array_like, shape (n_pings, n_range, n_beams)
    range_m : array_like, shape (n_range,)
        Increasing ranges (m).
    range_bin_m : float
        Bin height (m); bins start at the first range.
    ping_bin : int
        Pings per bin (the last bin may hold fewer).

    Returns
    -------
    mean_s_v : ndarray, shape (n_ping_bins, n_range_bins, n_beams)
        Mean s_v of the cells in each bin (m⁻¹); NaN for a bin with no cell.
    range_edges_m : ndarray, shape (n_range_bins + 1,)
    ping_edges : ndarray of int, shape (n_ping_bins + 1,)
        Ping rows; bin k holds rows ping_edges[k] ≤ p < ping_edges[k + 1].
    """
    s = np.asarray(s_v, float)
    r = np.asarray(range_m, float)
    if range_bin_m <= 0 or int(ping_bin) < 1:
        raise ValueError("range_bin_m must be positive and ping_bin at least 1")
    n_p = s.shape[0]
    n_rb = max(1, int(np.ceil((r[-1] - r[0]) / range_bin_m + 1e-9)))
    edges = r[0] + range_bin_m * np.arange(n_rb + 1)
    which = np.minimum(((r - r[0]) / range_bin_m).astype(int), n_rb - 1)
    pe = np.r_[np.arange(0, n_p, int(ping_bin)), n_p]
    out = np.full((pe.size - 1, n_rb, s.shape[2]), np.nan)
    cells = np.bincount(which, minlength=n_rb)
    for k in range(pe.size - 1):
        block = s[pe[k]:pe[k + 1]].sum(axis=0)                       # (n_range, n_beams)
        sums = np.zeros((n_rb, s.shape[2]))
        np.add.at(sums, which, block)
        count = cells * (pe[k + 1] - pe[k])
        with np.errstate(invalid="ignore", divide="ignore"):
            out[k] = np.where(count[:, None] > 0, sums / np.maximum(count, 1)[:, None], np.nan)
    return out, edges, pe


def nasc(s_v, range_m, layers_m) -> np.ndarray:
    """Nautical area scattering coefficient of range layers, per ping and beam.

    Parameters
    ----------
    s_v : array_like, shape (n_pings, n_range, n_beams)
    range_m : array_like, shape (n_range,)
        Uniformly spaced ranges (m).
    layers_m : array_like, shape (n_layers, 2)
        [start, stop] of each layer (m).

    Returns
    -------
    ndarray, shape (n_pings, n_layers, n_beams)
        NASC = 4π 1852² Σ s_v Δr over the cells of each layer (m² nmi⁻²); 0 for a layer that
        holds no cell.
    """
    s = np.asarray(s_v, float)
    r = np.asarray(range_m, float)
    dr = float(np.median(np.diff(r))) if r.size > 1 else 0.0
    lay = np.asarray(layers_m, float).reshape(-1, 2)
    out = np.zeros((s.shape[0], lay.shape[0], s.shape[2]))
    for i, (a, b) in enumerate(lay):
        rows = (r >= a) & (r < b)
        out[:, i] = 4 * np.pi * NMI_M**2 * s[:, rows].sum(axis=1) * dr
    return out


class LayerError(DatasetError):
    """A NASC layer that holds no range cell of the image (outside it, or thinner than a cell).

    Attributes
    ----------
    layer : int
        Its index in the layers given.
    """

    def __init__(self, message: str, layer: int):
        super().__init__(message)
        self.layer = layer


def _check_layers(layers, range_m, shape, range_bin_m: float, ping_bin: int,
                  max_memory_gb: float | None = None) -> None:
    """Every NASC layer holds at least one range cell of the image (else its NASC would be a
    meaningless 0); the MVBS grid of ``range_bin_m`` fits the memory limit (a bin of 1e-9 m
    would ask for billions of bins) — both checked before anything is allocated.

    Raises
    ------
    LayerError
        Names the layer and the image's range and cell size.
    processing.base.resources.ResourceError
        The grid would not fit the memory limit.
    """
    from processing.base.resources import Estimate, check_resources
    r = np.asarray(range_m, float)
    cell = float(np.median(np.diff(r))) if r.size > 1 else 0.0
    for k, (a, b) in enumerate(np.asarray(layers, float).reshape(-1, 2)):
        if not np.any((r >= a) & (r < b)):
            where = ("outside the image" if b <= r[0] or a > r[-1] else
                     f"thinner than the image's range cells ({cell:.4g} m) and holds none")
            raise LayerError(f"layer {a:g}–{b:g} m is {where}: the image covers {r[0]:.3f}–{r[-1]:.3f} m "
                             f"in cells of {cell:.4g} m; give layers inside it, at least one cell thick", k)
    n_pings, _, n_beams = shape
    span = float(r[-1] - r[0]) if r.size else 0.0
    n_bins = span / range_bin_m + 1.0 if range_bin_m > 0 else np.inf
    n_ping_bins = np.ceil(n_pings / max(int(ping_bin), 1))
    # the grid (mean s_v, Sv, per-bin sums) and a CSV row per cell: ≈ 6 float64 per cell and bin
    grid = n_ping_bins * n_bins * n_beams * 8.0 * 6 + n_bins * n_beams * 8.0
    check_resources(Estimate(grid, 0.0, [("MVBS grid", grid)],
                             keys=f"the MVBS range bins ({range_bin_m:g} m over {span:.3g} m: {n_bins:.3g} "
                                  f"bins per beam; give a larger range bin)"),
                    what="the Sv grid", max_memory_gb=max_memory_gb)


def backscatter(tree, settings=None, *, range_bin_m: float = 0.5, ping_bin: int = 10,
                layers_m=None, image_group: str | None = None, max_memory_gb: float | None = None,
                cells: bool = False):
    """Sv products of a dataset: MVBS on a (ping bin, range bin, beam) grid and NASC of range
    layers per ping and beam, written to /Processing/Sv.

    Parameters
    ----------
    tree : xarray.DataTree
        A dataset with samples and a calibration (/Sonar/calibration_gain, …); imaged here.
    settings : ProcessingSettings, dict or path, optional
        Image settings and the detector's noise estimate (subtracted: 2σ² per cell).
    range_bin_m : float
        MVBS bin height (m).
    ping_bin : int
        Pings per MVBS bin.
    layers_m : array_like, shape (n_layers, 2), optional
        NASC layers [start, stop] (m); default one layer, the image's range.
    image_group : str, optional
        Subarray whose image is used (default: the detector's).
    max_memory_gb : float, optional
        The memory limit the MVBS grid must fit (default:
        :func:`processing.base.resources.memory_limit_bytes`).
    cells : bool
        Also keep every cell: ``Sv`` (dB, NaN where noise only) and ``s_v`` (m⁻¹, linear, may be
        negative after noise subtraction: average *this* elsewhere) on (ping_row, range_cell,
        beam), with ``cell_range_m``. Always kept for a Simrad power record.

    An EK60 power record converted by echopype (:mod:`processing.base.echosounder`) is
    calibrated sample by sample with the Simrad/echopype equation
    (:mod:`processing.backscatter.ek60`): each channel is one beam, its cells the samples, the
    MVBS bins start at 0 m of ``echo_range`` and skip samples without Sv. An EK80 file is
    refused by name (echopype calibrates it).

    Returns
    -------
    xarray.DataTree
        A copy with /Processing/Sv: ``Sv_mean`` (dB re 1 m⁻¹, NaN where the bin holds noise
        only) and ``s_v_mean`` (m⁻¹) on (ping_bin, range_bin, beam); ``NASC`` (m² nmi⁻²) on
        (ping_time, layer, beam); bin edges and beam angles as coordinates.

    Raises
    ------
    LayerError
        A layer that holds no range cell of the image (its NASC would be a meaningless 0).
    processing.base.resources.ResourceError
        A grid (``range_bin_m``) too fine for the memory limit, refused before it is allocated.
    """
    import xarray as xr

    from processing.backscatter.calibration import beam_solid_angle_sr, calibration_of, range_energy_width_m
    from processing.detection.detect import noise_fit
    from processing.detection.noise import NoiseEstimateError
    from processing.imaging.beamforming import SubarrayGeometry
    from processing.imaging.compression import RangeFilter
    from processing.base.dataset import as_tree
    from processing.base.echosounder import is_power_record
    from processing.pipeline import RecordChain
    tree = as_tree(tree)
    if is_power_record(tree):
        return _power_backscatter(tree, range_bin_m=range_bin_m, ping_bin=ping_bin, layers_m=layers_m,
                                  max_memory_gb=max_memory_gb)
    chain = RecordChain(tree, settings)
    tree, st = chain.tree, chain.settings
    group = image_group or st.detect.image_group
    cal = calibration_of(tree)                  # names what is missing
    im = chain.images()
    if group not in im.groups:
        raise DatasetError(f"no image of subarray {group!r} (has {', '.join(im.groups)})")
    g = list(im.groups).index(group)
    mags = np.abs(im.image[:, g])
    rec = chain.record
    rf = RangeFilter.design(rec.replica, n_samples=rec.samples.shape[-1], rate_hz=rec.rate_hz,
                            bandwidth_hz=rec.bandwidth_hz, range_window=st.image.range_window)
    geo = SubarrayGeometry(rec.element_position_m[rec.image_groups[group]], st.image.spatial_window)
    l_r = range_energy_width_m(rf, rec.sound_speed_m_s)
    psi = beam_solid_angle_sr(cal, geo, im.beam_angle_rad, rec.wavelength_m)
    sigma = 0.0
    if st.detect.needs_noise or st.detect.noise.source != "image":
        try:
            sigma = noise_fit(mags, st.detect, im.range_m, im.beam_angle_rad, im.interpolation).sigma
        except NoiseEstimateError:
            sigma = 0.0
    s_v = sv_cells(mags, im.range_m, gain_counts_m=cal.gain_counts_m,
                   absorption_db_per_m=cal.absorption_db_per_m, range_width_m=l_r,
                   solid_angle_sr=psi, noise_power=2 * sigma**2)
    layers = np.asarray(layers_m if layers_m is not None else [[im.range_m[0], im.range_m[-1] + 1e-9]],
                        float).reshape(-1, 2)
    _check_layers(layers, im.range_m, mags.shape, range_bin_m, ping_bin, max_memory_gb)
    if cells:        # Sv, s_v and their ranges, float64, and the dB copy made on the way
        from processing.base.resources import Estimate, check_resources
        size = float(mags.size) * 8.0 * 4
        check_resources(Estimate(size, 0.0, [("Sv cells", size)],
                                 keys="the pings (the cells of every ping are kept: give fewer pings)"),
                        what="the Sv cells (--cells)", max_memory_gb=max_memory_gb)
    grid, r_edges, p_edges = mean_volume_backscatter(s_v, im.range_m, range_bin_m=range_bin_m,
                                                     ping_bin=ping_bin)
    area = nasc(s_v, im.range_m, layers)
    beams = np.degrees(im.beam_angle_rad)
    ds = xr.Dataset(
        {"Sv_mean": (("ping_bin", "range_bin", "beam"), sv_db(grid)),
         "s_v_mean": (("ping_bin", "range_bin", "beam"), grid),
         "NASC": (("ping_row", "layer", "beam"), area),
         "range_bin_start_m": ("range_bin", r_edges[:-1]), "range_bin_stop_m": ("range_bin", r_edges[1:]),
         "ping_bin_first_row": ("ping_bin", p_edges[:-1]), "ping_bin_last_row": ("ping_bin", p_edges[1:] - 1),
         "layer_start_m": ("layer", layers[:, 0]), "layer_stop_m": ("layer", layers[:, 1]),
         "beam_angle_deg": ("beam", beams)},
        attrs={"image_group": group, "noise_sigma_counts": float(sigma),
               "range_energy_width_m": l_r, "range_bin_m": float(range_bin_m), "ping_bin": int(ping_bin),
               "calibration_gain_counts_m": float(cal.gain_counts_m),
               "absorption_db_per_m": float(cal.absorption_db_per_m),
               "sound_speed_m_s": float(rec.sound_speed_m_s), "center_frequency_hz": float(rec.center_frequency_hz)})
    ds["solid_angle_sr"] = ("beam", np.asarray(psi, float))
    ds["solid_angle_sr"].attrs.update(units="sr", long_name="two-way equivalent solid angle of each beam (Ψ_b)")
    ds["Sv_mean"].attrs.update(units="dB re 1 m-1", nan_means="noise only (s_v ≤ 0 after noise subtraction)")
    ds["s_v_mean"].attrs["units"] = "m-1"
    ds["NASC"].attrs.update(units="m2 nmi-2", long_name="4π 1852² ∫ s_v dr along the beam over the layer")
    if cells:
        _add_cells(ds, s_v, np.broadcast_to(np.asarray(im.range_m, float)[None, :, None], s_v.shape))
    out = tree.copy()
    out[SV_GROUP] = xr.DataTree(ds)
    return out


def _add_cells(ds, s_v, cell_range_m) -> None:
    """Every cell's Sv (dB) and s_v (linear) on (ping_row, range_cell, beam), with its range."""
    dims = ("ping_row", "range_cell", "beam")
    ds["Sv"] = (dims, sv_db(s_v))
    ds["Sv"].attrs.update(units="dB re 1 m-1", long_name="volume backscattering strength of each cell",
                          nan_means="no Sv: s_v <= 0 after noise subtraction (average s_v, not Sv)")
    ds["s_v"] = (dims, np.asarray(s_v, float))
    ds["s_v"].attrs.update(units="m-1", long_name="volume backscattering coefficient of each cell (linear; "
                           "negative where noise subtraction leaves less than nothing)",
                           nan_means="no sample (before the time-varied gain starts or past the ping's end)")
    ds["cell_range_m"] = (dims, np.ascontiguousarray(cell_range_m, float))
    ds["cell_range_m"].attrs.update(units="m", nan_means="no sample")


def _grid_cells(s_v, cell_range_m, edges, ping_edges) -> np.ndarray:
    """Mean s_v of the finite cells of each (ping bin, range bin, beam), cells binned by their
    own range (left-closed bins); NaN for a bin with none. Shapes: s_v and cell_range_m
    (n_pings, n_cells, n_beams); returns (n_ping_bins, n_range_bins, n_beams)."""
    n_rb = edges.size - 1
    out = np.full((ping_edges.size - 1, n_rb, s_v.shape[2]), np.nan)
    ok = np.isfinite(s_v) & np.isfinite(cell_range_m)
    which = np.clip(np.searchsorted(edges, np.where(ok, cell_range_m, 0.0), side="right") - 1, 0, n_rb - 1)
    for k in range(ping_edges.size - 1):
        rows = slice(ping_edges[k], ping_edges[k + 1])
        for b in range(s_v.shape[2]):
            m = ok[rows, :, b]
            w = which[rows, :, b][m]
            sums = np.bincount(w, weights=s_v[rows, :, b][m], minlength=n_rb)
            count = np.bincount(w, minlength=n_rb)
            with np.errstate(invalid="ignore", divide="ignore"):
                out[k, :, b] = np.where(count > 0, sums / np.maximum(count, 1), np.nan)
    return out


def _power_backscatter(tree, *, range_bin_m: float, ping_bin: int, layers_m, max_memory_gb):
    """:func:`backscatter` of a Simrad power record (each channel one beam, each sample a cell)."""
    import xarray as xr

    from processing.backscatter.ek60 import CSV_TERMS, sv_of_power
    from processing.base.dataset import source_of
    from processing.base.echosounder import annotate_missing, read_power_record
    from processing.base.resources import Estimate, check_resources
    rec = read_power_record(tree, source=source_of(tree))
    sv, r = sv_of_power(rec)                                   # (channel, ping, sample)
    sv, r = sv.transpose(1, 2, 0), r.transpose(1, 2, 0)        # (ping, cell, beam)
    with np.errstate(over="ignore"):
        s_v = np.where(np.isfinite(sv), 10.0 ** (sv / 10.0), np.nan)
    top = float(np.nanmax(r)) if np.isfinite(r).any() else 0.0
    n_rb = max(1, int(np.ceil(top / range_bin_m + 1e-9)))
    grid_bytes = -(-sv.shape[0] // int(ping_bin)) * n_rb * sv.shape[2] * 8.0 * 6
    check_resources(Estimate(grid_bytes, 0.0, [("MVBS grid", grid_bytes)],
                             keys=f"the MVBS range bins ({range_bin_m:g} m over {top:.3g} m; give a larger range bin)"),
                    what="the Sv grid", max_memory_gb=max_memory_gb)
    edges = range_bin_m * np.arange(n_rb + 1)
    pe = np.r_[np.arange(0, sv.shape[0], int(ping_bin)), sv.shape[0]]
    grid = _grid_cells(s_v, r, edges, pe)
    layers = np.asarray(layers_m if layers_m is not None else [[0.0, top + 1e-9]], float).reshape(-1, 2)
    dr = (rec.sample_interval_s * rec.sound_speed_m_s / 2.0).T          # (ping, beam)
    area = np.zeros((sv.shape[0], layers.shape[0], sv.shape[2]))
    for i, (a, b) in enumerate(layers):
        inside = np.isfinite(s_v) & (r >= a) & (r < b)
        if not inside.any():
            raise LayerError(f"layer {a:g}–{b:g} m holds no sample with Sv: the record covers "
                             f"0–{top:.3f} m", i)
        area[:, i] = 4 * np.pi * NMI_M**2 * np.where(inside, s_v, 0.0).sum(axis=1) * dr
    ds = xr.Dataset(
        {"Sv_mean": (("ping_bin", "range_bin", "beam"), sv_db(grid)),
         "s_v_mean": (("ping_bin", "range_bin", "beam"), grid),
         "NASC": (("ping_row", "layer", "beam"), area),
         "range_bin_start_m": ("range_bin", edges[:-1]), "range_bin_stop_m": ("range_bin", edges[1:]),
         "ping_bin_first_row": ("ping_bin", pe[:-1]), "ping_bin_last_row": ("ping_bin", pe[1:] - 1),
         "layer_start_m": ("layer", layers[:, 0]), "layer_stop_m": ("layer", layers[:, 1]),
         "beam_angle_deg": ("beam", np.zeros(sv.shape[2]))},
        coords={"beam": rec.channel},
        attrs={"image_group": "", "noise_sigma_counts": 0.0, "range_bin_m": float(range_bin_m),
               "ping_bin": int(ping_bin), "calibration": f"{rec.model} power: Sv = P_r + 20 log10 r' + 2 α r' − "
               f"({CSV_TERMS}) − 2 S_a (processing/backscatter/ek60.py)"})
    ds["Sv_mean"].attrs.update(units="dB re 1 m-1", nan_means="no sample with Sv in the bin")
    ds["s_v_mean"].attrs.update(units="m-1", nan_means="no sample with Sv in the bin")
    ds["NASC"].attrs.update(units="m2 nmi-2", long_name="4π 1852² ∫ s_v dr along the beam over the layer")
    _add_cells(ds, s_v, r)
    ds["Sv"].attrs["nan_means"] = "no Sv: before the time-varied gain starts (r' <= 0) or past the ping's end"
    out = annotate_missing(tree)
    out[SV_GROUP] = xr.DataTree(ds)
    return out


#: the public name (``processing.sv``): calibrated Sv products of a dataset
sv = backscatter


def _write_rows(path, header, rows, empty: str = ""):
    import csv
    from pathlib import Path

    from processing.base.atomic import staged
    path = Path(path)
    with staged(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([empty if isinstance(x, float) and not np.isfinite(x) else
                        (f"{x:.9g}" if isinstance(x, float) else x) for x in r])
    return path


#: what an empty cell (no Sv) is written as in the CSV exports: a blank, or Echoview's −999
EMPTY_VALUES = {"blank": "", "-999": "-999"}


def _empty(empty: str) -> str:
    if empty not in EMPTY_VALUES:
        raise ValueError(f"empty must be one of {', '.join(EMPTY_VALUES)}, not {empty!r}")
    return EMPTY_VALUES[empty]


def write_mvbs_csv(tree, path, *, empty: str = "blank"):
    """One row per MVBS cell of /Processing/Sv (columns close to Echoview's integration-by-cells
    export: Interval, Ping_S, Ping_E, Layer, Range_start, Range_stop (m), Beam_angle (deg),
    Sv_mean (dB re 1 m⁻¹), s_v_mean (m⁻¹)); atomic. A cell without Sv (noise only, no sample)
    is written blank, or −999 as Echoview writes it (``empty="-999"``)."""
    ds = tree[SV_GROUP].ds
    sv, lin = ds["Sv_mean"].values, ds["s_v_mean"].values
    rows = []
    for i in range(sv.shape[0]):
        for j in range(sv.shape[1]):
            for b in range(sv.shape[2]):
                rows.append([i, int(ds["ping_bin_first_row"][i]), int(ds["ping_bin_last_row"][i]), j,
                             float(ds["range_bin_start_m"][j]), float(ds["range_bin_stop_m"][j]),
                             float(ds["beam_angle_deg"][b]), float(sv[i, j, b]), float(lin[i, j, b])])
    return _write_rows(path, ["Interval", "Ping_S", "Ping_E", "Layer", "Range_start", "Range_stop",
                              "Beam_angle", "Sv_mean", "s_v_mean"], rows, _empty(empty))


def write_cells_csv(tree, path, *, empty: str = "blank"):
    """One row per cell of /Processing/Sv (kept with ``cells=True``, always for a Simrad
    record): Ping, Range (m), Beam (its angle in deg, or the channel), Sv (dB re 1 m⁻¹, blank or
    −999 where there is none) and s_v (m⁻¹, linear: the value to average); atomic.

    Raises
    ------
    DatasetError
        /Processing/Sv holds no cells (made without ``cells``).
    """
    ds = tree[SV_GROUP].ds
    if "s_v" not in ds:
        raise DatasetError(f"/{SV_GROUP} holds no cells: make it with cells=True (abacus sv --cells)")
    sv, lin, rng = ds["Sv"].values, ds["s_v"].values, ds["cell_range_m"].values
    beams = (ds["beam"].values.astype(str) if "beam" in ds.coords
             else [f"{x:.9g}" for x in ds["beam_angle_deg"].values])
    rows = [[p, float(rng[p, j, b]), beams[b], float(sv[p, j, b]), float(lin[p, j, b])]
            for p in range(sv.shape[0]) for b in range(sv.shape[2]) for j in range(sv.shape[1])
            if np.isfinite(rng[p, j, b])]
    return _write_rows(path, ["Ping", "Range", "Beam", "Sv", "s_v"], rows, _empty(empty))


def write_nasc_csv(tree, path):
    """One row per (ping, layer, beam) of /Processing/Sv: Ping, Layer, Range_start, Range_stop
    (m), Beam_angle (deg), NASC (m² nmi⁻²); atomic."""
    ds = tree[SV_GROUP].ds
    area = ds["NASC"].values
    rows = [[p, k, float(ds["layer_start_m"][k]), float(ds["layer_stop_m"][k]),
             float(ds["beam_angle_deg"][b]), float(area[p, k, b])]
            for p in range(area.shape[0]) for k in range(area.shape[1]) for b in range(area.shape[2])]
    return _write_rows(path, ["Ping", "Layer", "Range_start", "Range_stop", "Beam_angle", "NASC"], rows)
