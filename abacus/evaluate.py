"""Per-ping evaluation of a dataset under several processing settings at once: what an experiment
(thesis chapter 6) records for every ping and every sweep point.

The images are formed once per distinct image setting and reused by every detection setting;
for each setting the pings are detected, located, counted and scored against the ground truth
(when the dataset has it), and echo integration gives s_v and, with the counted density, the mean
backscattering cross-section (thesis §1.4).
"""
from __future__ import annotations

import numpy as np
import xarray as xr

from processing.imaging.beamforming import SubarrayGeometry
from processing.imaging.compression import RangeFilter
from processing.base.dataset import TRUTH_GROUP, read_record, source_of
from processing.detection.detect import candidates, noise_fit, ping_thresholds, refit_elevations, score_all, select
from processing.detection.sidelobes import counted_sidelobes
from processing.imaging.images import form_images
from processing.backscatter.calibration import beam_solid_angle_sr, calibration_of, range_energy_width_m
from processing.backscatter.echo_integration import volume_backscattering
from processing.detection.noise import NoiseEstimateError
from processing.settings import ProcessingSettings

__all__ = ["evaluate", "NOISE_BINS", "PER_PING_KEYS"]

#: bins of |I|/σ̂ for the noise histogram (thesis Fig. 6.13)
NOISE_BINS = np.linspace(0.0, 6.0, 121)

#: what :func:`evaluate` returns per (setting, ping), in this order
PER_PING_KEYS = ("true_in_volume", "true_in_span", "count_before", "count_after",
                 "error_before", "error_after", "hits_before", "misses_before",
                 "false_alarms_before", "hits_after", "misses_after", "false_alarms_after",
                 "shared_cell_misses", "density_per_m3", "true_density_per_m3", "threshold_counts",
                 "noise_sigma_counts", "s_v_per_m", "sigma_bs_m2", "true_sigma_bs_m2")


def _truth(tree, ping_index):
    if TRUTH_GROUP.split("/")[0] not in tree.children:
        return None
    try:
        gt = tree[TRUTH_GROUP].ds
    except KeyError:
        return None
    index_of = {int(p): i for i, p in enumerate(ping_index)}
    pings = gt["target_ping_index"].values.astype(int)
    keep = np.array([p in index_of for p in pings], bool)
    return {"ping": np.array([index_of[p] for p in pings[keep]], int),
            "position_m": np.stack([gt[f"target_{a}"].values for a in "xyz"], -1)[keep],
            "rho_m": gt["target_backscatter_amplitude"].values[keep]}


def evaluate(tree: xr.DataTree, settings_list) -> dict:
    """Counts, scores and echo integration of every ping under every setting.

    Parameters
    ----------
    tree : xarray.DataTree
        A dataset following the data contract (usually one simulated ping).
    settings_list : sequence of ProcessingSettings

    Returns
    -------
    dict
        ``per_ping``: {key: ndarray (n_settings, n_pings)} for every key of PER_PING_KEYS (NaN
        where it does not apply: no truth, no noise, no calibration, nothing counted);
        ``noise_histogram``: ndarray (n_pings, len(NOISE_BINS) − 1), counts of |I|/σ̂ over the
        noise cells of the first setting (zeros without a noise estimate);
        ``notes``: list of str.
    """
    from processing import pipeline as products
    settings_list = [products.resolve_settings(tree, s) for s in settings_list]
    rec = read_record(tree, source=source_of(tree))
    n_pings = rec.samples.shape[0]
    n_set = len(settings_list)
    out = {k: np.full((n_set, n_pings), np.nan) for k in PER_PING_KEYS}
    hist = np.zeros((n_pings, NOISE_BINS.size - 1))
    notes: list[str] = []
    pose = products.pose_of(tree)
    try:
        cal = calibration_of(tree)
    except Exception as exc:  # a recorded dataset without calibration: counts still work
        cal = None
        notes.append(f"no echo integration: {exc}")
    truth = _truth(tree, rec.ping_index)
    imaged: dict[str, object] = {}      # image settings -> Images (formed once)
    equivalent: dict = {}     # (image settings, group) -> (L_r, Ψ_b): once per image
    noise: dict = {}          # (image settings, group, noise settings) -> σ̂ per ping
    integrated: dict = {}     # (image, group, noise, volume) -> s_v per ping
    # 1. thresholds of every setting; settings that differ only in their threshold (a sweep)
    #    share one pool of candidate peaks, described once
    plans = []
    for st in settings_list:
        if st.count.coincidence_correction != "none" or st.count.volume_edge != "hard":
            notes.append("count.coincidence_correction and count.volume_edge are not applied in an "
                         "experiment's per-ping counts (the hard, uncorrected counts; abacus count "
                         "applies them)")
        key = st.image.model_dump_json()
        if key not in imaged:
            imaged[key] = form_images(rec, st.image, noise_band_hz=products.noise_band_of(tree))
        im = imaged[key]
        volume = products.volume_of(tree, st, image_range_m=(im.range_m[0], im.range_m[-1]))
        mags = np.abs(im.image[:, im.group_index(st.detect.image_group)])
        thr = ping_thresholds(mags, st.detect, im.range_m, im.beam_angle_rad, volume,
                              upsample=im.interpolation)
        if thr.noise is not None and not thr.noise.rayleigh_like:
            notes.append(f"the noise cells are not Rayleigh-like ({thr.noise.describe()})")
        pool_key = (key, st.detect.image_group, volume)
        plans.append((st, key, im, volume, mags, thr, pool_key))
    floors: dict = {}
    for _, _, _, _, _, thr, pool_key in plans:
        floors[pool_key] = thr if pool_key not in floors else floors[pool_key].floor(thr)
    pools = {k: candidates(imaged[k[0]], rec, settings_list[0].detect.model_copy(
                 update={"image_group": k[1]}), f.per_ping, k[2], pose=pose)
             for k, f in floors.items()}
    for i, (st, key, im, volume, mags, thr, pool_key) in enumerate(plans):
        table = select(pools[pool_key], thr)
        if st.detect.elevation == "fit":
            refit_elevations(table, im, rec, volume, pose=pose)
        side = counted_sidelobes(table, rec, st.count, range_resolution_m=im.range_resolution_m,
                                 azimuth_resolution_rad=im.azimuth_resolution_rad,
                                 image_group=st.detect.image_group)
        res = score_all(table, truth, volume, n_pings, dr=im.range_resolution_m,
                        dtheta=im.azimuth_resolution_rad, gate=st.count.gate_cells,
                        unresolved=st.count.unresolved_cells, sidelobe=side)
        for k, v in res.items():
            if k in out:
                out[k][i] = v
        out["threshold_counts"][i] = thr.median
        # noise: the detector's own estimate where it has one (a region or a noise file); a
        # median over an image full of fish or sidelobes is no noise level to subtract
        sigma = np.zeros(n_pings)
        if st.detect.needs_noise or st.detect.noise.source != "image":
            n_key = (key, st.detect.image_group, st.detect.noise.model_dump_json())
            if n_key not in noise:
                for p in range(n_pings):
                    try:
                        sigma[p] = noise_fit(mags[p:p + 1], st.detect, im.range_m,
                                             im.beam_angle_rad, im.interpolation).sigma
                    except NoiseEstimateError:
                        sigma[p] = 0.0
                noise[n_key] = sigma
            sigma = noise[n_key]
        out["noise_sigma_counts"][i] = np.where(sigma > 0, sigma, np.nan)
        if i == 0 and np.any(sigma > 0):
            hist = _noise_histogram(mags, sigma, st, im)
        if cal is not None:
            ei_key = (key, st.detect.image_group)
            if ei_key not in equivalent:
                rf = RangeFilter.design(rec.replica, n_samples=rec.samples.shape[-1], rate_hz=rec.rate_hz,
                                        bandwidth_hz=rec.bandwidth_hz, range_window=st.image.range_window)
                geo = SubarrayGeometry(rec.element_position_m[rec.image_groups[st.detect.image_group]],
                                       st.image.spatial_window)
                equivalent[ei_key] = (range_energy_width_m(rf, rec.sound_speed_m_s),
                                      beam_solid_angle_sr(cal, geo, im.beam_angle_rad, rec.wavelength_m))
            l_r, psi = equivalent[ei_key]
            sv_key = (key, st.detect.image_group, sigma.tobytes(), volume)
            if sv_key not in integrated:
                integrated[sv_key] = volume_backscattering(
                    mags, im.range_m, im.beam_angle_rad, volume, cal, range_width_m=l_r,
                    solid_angle_sr=psi, noise_power=2 * sigma**2)
            sv = integrated[sv_key]
            out["s_v_per_m"][i] = sv
            dens = res["density_per_m3"]
            with np.errstate(divide="ignore", invalid="ignore"):
                out["sigma_bs_m2"][i] = np.where(dens > 0, sv / dens, np.nan)
        if truth is not None:
            inside = volume.contains(truth["position_m"])
            for p in range(n_pings):
                k = inside & (truth["ping"] == p)
                if k.any():
                    out["true_sigma_bs_m2"][i, p] = float(np.mean(truth["rho_m"][k] ** 2))
    return {"per_ping": out, "noise_histogram": hist, "notes": sorted(set(notes))}


def _noise_histogram(mags, sigma, st: ProcessingSettings, im) -> np.ndarray:
    """Counts of |I|/σ̂ over the noise cells of each ping (native range samples only)."""
    ns = st.detect.noise
    r, th = im.range_m, im.beam_angle_rad
    rows = np.ones(r.size, bool)
    cols = np.ones(th.size, bool)
    if ns.source == "region":
        rows = (r >= ns.range_m[0]) & (r <= ns.range_m[1])
        if ns.azimuth is not None:
            cols = (th >= ns.azimuth[0]) & (th <= ns.azimuth[1])
    rows[np.arange(r.size) % max(im.interpolation, 1) != 0] = False
    out = np.zeros((mags.shape[0], NOISE_BINS.size - 1))
    for p in range(mags.shape[0]):
        if sigma[p] > 0:
            out[p] = np.histogram(mags[p][rows][:, cols].ravel() / sigma[p], bins=NOISE_BINS)[0]
    return out
