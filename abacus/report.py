"""The report of an experiment: the thesis' chapter-6 figures for the scene at hand, as PNGs and
one self-contained HTML page (images embedded), from the results dataset alone.

Figures (thesis numbering): counts vs ping (6.5, 6.8, 6.18), count error before and after
interferometry (6.9, 6.11, 6.15, 6.19), the noise PDF with its Rayleigh fit (6.13), mean error vs
the swept parameter with the derived threshold marked (6.22), density vs ping (6.25), target
strength from echo integration and the counted density (§1.4), and the fan-beam images with
detections the run kept (Appendix B). Every axis names its quantity and unit.
"""
from __future__ import annotations

import base64
import html
import json
from pathlib import Path

import numpy as np
import xarray as xr

from processing.base.atomic import write_text_atomic
from processing.detection.noise import rayleigh_mean
from abacus.figures.plots import fixed_layout, save as _save_png

__all__ = ["write_report", "report_figures", "plateau", "PLATEAU_TARGETS"]


def save(fig, path):
    """Fixed margins (no layout engine: it would double each figure's cost), then write."""
    fixed_layout(fig, left=0.85, right=0.3, bottom=0.65, top=0.35, wspace=0.3)
    return _save_png(fig, path)


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def derived_in_sweep_units(ds: xr.Dataset):
    """The scene's own (derived) threshold in the units of a threshold sweep, or None."""
    if ds.attrs.get("sweep_key") != "threshold":
        return None
    settings = json.loads(ds.attrs["settings_json"])
    t = float(np.nanmedian(ds["threshold_counts"].isel(setting=0)))
    if not np.isfinite(t):
        return None
    det = settings[1]["detect"] if len(settings) > 1 else settings[0]["detect"]
    units = det.get("value_units", "counts")
    if units == "counts":
        return t
    sigma = float(np.nanmedian(ds["noise_sigma_counts"].isel(setting=0)))
    if not np.isfinite(sigma) or sigma <= 0:
        return None
    mu = rayleigh_mean(sigma)
    return t / mu * (det.get("thesis_noise_mean", 139.8) if units == "thesis" else 1.0)


def threshold_units(ds: xr.Dataset):
    """The one unit every threshold of the report is given in: the scene's ``value_units``
    (those of a threshold sweep), as (units, noise mean in those units, axis label). ``counts``:
    ADC counts (the noise mean is then None: it varies with the noise); ``noise_mean``:
    multiples of the noise mean μ̂; ``thesis``: the thesis' image units, in which μ̂ reads
    ``thesis_noise_mean`` (139.8, Table 6.5)."""
    settings = json.loads(ds.attrs["settings_json"])
    det = settings[-1]["detect"]         # a threshold sweep's (the scene's own otherwise)
    units = det.get("value_units", "counts")
    mu = {"counts": None, "noise_mean": 1.0, "thesis": float(det.get("thesis_noise_mean", 139.8))}[units]
    label = {"counts": "threshold T (ADC counts)",
             "noise_mean": "threshold T (multiples of the noise mean μ̂)",
             "thesis": f"threshold T (thesis image units: the noise mean μ̂ = {mu or 0:g})"}[units]
    return units, mu, label


def _sweep_axis_label(ds: xr.Dataset) -> str:
    key = ds.attrs.get("sweep_key", "")
    if key == "threshold":
        return threshold_units(ds)[2]
    return f"{ds.attrs.get('sweep_path', key)} (scene units: SI, see the scene file)"


#: a sweep point is on the plateau when its mean count error after interferometry is within this
#: many targets per ping of zero (the thesis reads its plateau off Fig. 6.22 by eye)
PLATEAU_TARGETS = 0.5


def plateau(ds: xr.Dataset, tolerance: float = PLATEAU_TARGETS):
    """(low, high) sweep values of the longest run of sweep points whose mean count error after
    interferometry lies within ±``tolerance`` targets per ping; None without a sweep or truth."""
    if ds.sizes["setting"] < 2 or not np.isfinite(ds["error_after_mean"].values[1:]).any():
        return None
    v = ds["sweep_value"].values[1:]
    ok = np.abs(ds["error_after_mean"].values[1:]) <= tolerance
    best, start = None, None
    for i, flag in enumerate(np.append(ok, False)):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            if best is None or i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    return None if best is None else (float(v[best[0]]), float(v[best[1] - 1]))


def report_figures(ds: xr.Dataset, outdir) -> list[tuple[str, Path, str]]:
    """Write the figures; returns (title, path, caption) of each.

    Parameters
    ----------
    ds : xarray.Dataset
        An experiment's results (abacus.experiment).
    outdir : path
        Folder for the PNGs (created).
    """
    plt = _plt()
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    figs = []
    base = ds.isel(setting=0)
    ping = ds["ping"].values
    has_truth = bool(np.isfinite(base["true_in_volume"].values).any())
    # counts vs ping
    fig, ax = plt.subplots(figsize=(9, 4))
    if has_truth:
        ax.plot(ping, base["true_in_volume"], "k-", lw=1.3, label="true, in the counting volume")
    ax.plot(ping, base["count_before"], "-", color="tab:orange", lw=1, label="detected in span (before interferometry)")
    ax.plot(ping, base["count_after"], "-", color="tab:green", lw=1, label="counted in volume (after interferometry)")
    ax.set_xlabel("ping index")
    ax.set_ylabel("targets per ping (count)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    figs.append(("Counts per ping (thesis Figs. 6.5, 6.8, 6.18)", save(fig, outdir / "counts.png"),
                 "Targets detected in the counting span before interferometry, counted inside the "
                 "counting volume after it, and the truth."))
    plt.close(fig)
    if has_truth:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4),
                                 gridspec_kw={"width_ratios": [3, 1]})
        eb, ea = base["error_before"].values, base["error_after"].values
        axes[0].plot(ping, eb, "-", color="tab:orange", lw=1, label="before interferometry")
        axes[0].plot(ping, ea, "-", color="tab:green", lw=1, label="after interferometry")
        axes[0].axhline(0, color="k", lw=0.8)
        axes[0].set_xlabel("ping index")
        axes[0].set_ylabel("count error, counted − true (targets)")
        axes[0].grid(alpha=0.3)
        axes[0].legend(fontsize=8)
        lo, hi = int(np.nanmin([eb.min(), ea.min()])), int(np.nanmax([eb.max(), ea.max()]))
        bins = np.arange(lo - 0.5, hi + 1.5)
        axes[1].hist(eb, bins=bins, orientation="horizontal", alpha=0.6, color="tab:orange")
        axes[1].hist(ea, bins=bins, orientation="horizontal", alpha=0.6, color="tab:green")
        axes[1].set_xlabel("pings (count)")
        axes[1].set_ylabel("count error (targets)")
        figs.append(("Count error (thesis Figs. 6.9, 6.11, 6.15, 6.19)", save(fig, outdir / "count_error.png"),
                     f"Before: {np.mean(eb):+.2f} ± {np.std(eb):.2f}; after: {np.mean(ea):+.2f} ± "
                     f"{np.std(ea):.2f} targets per ping (mean ± standard deviation)."))
        plt.close(fig)
    # noise PDF, in the unit the thresholds are given in
    hist = ds["noise_histogram"].values.sum(axis=0)
    if hist.sum() > 0:
        edges = ds["noise_bin_edge"].values          # in units of each ping's own σ̂
        sig = float(np.nanmean(base["noise_sigma_counts"]))
        units, mu_units, _ = threshold_units(ds)
        # σ̂ in the report's threshold unit: counts, or the noise mean μ̂ = σ̂ √(π/2) read as mu_units
        scale = sig if mu_units is None else mu_units / rayleigh_mean(1.0)
        unit_name = {"counts": "ADC counts", "noise_mean": "multiples of μ̂",
                     "thesis": "thesis image units"}[units]
        x = 0.5 * (edges[1:] + edges[:-1]) * scale
        width = np.diff(edges) * scale
        pdf = hist / (hist.sum() * width)
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.bar(x, pdf, width=width, color="0.75", label="noise cells")
        xx = np.linspace(0, edges[-1] * scale, 400)
        ax.plot(xx, xx / scale**2 * np.exp(-xx**2 / (2 * scale**2)), "r-",
                label=f"Rayleigh, σ = {sig:.4g} ADC counts (μ = {rayleigh_mean(sig):.4g})")
        t_counts = float(np.nanmedian(base["threshold_counts"]))
        sig_med = float(np.nanmedian(base["noise_sigma_counts"]))
        if np.isfinite(t_counts) and sig_med > 0:
            # as the summary and the sweep convert it: with the median σ̂ of the pings
            t = t_counts if mu_units is None else t_counts / rayleigh_mean(sig_med) * mu_units
            ax.axvline(t, color="tab:red", ls="--", label=f"the scene's threshold ({t:.4g})")
        ax.set_xlabel(f"|I| in the noise cells ({unit_name})")
        ax.set_ylabel(f"probability density (1 / {unit_name})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        figs.append(("Noise PDF (thesis Fig. 6.13)", save(fig, outdir / "noise_pdf.png"),
                     f"{int(hist.sum()):,} noise cells (native range samples) of all pings, each "
                     f"ping normalised by its own σ̂, against the Rayleigh law; |I| in {unit_name}, "
                     "the unit of every threshold in this report."))
        plt.close(fig)
    # mean error vs sweep
    if ds.sizes["setting"] > 1:
        sw = ds.isel(setting=slice(1, None))
        v = sw["sweep_value"].values
        fig, ax = plt.subplots(figsize=(8, 4.5))
        if has_truth:
            ax.errorbar(v, sw["error_before_mean"], yerr=sw["error_before_std"], fmt="s-", ms=3,
                        color="tab:orange", capsize=2, label="before interferometry")
            ax.errorbar(v, sw["error_after_mean"], yerr=sw["error_after_std"], fmt="o-", ms=3,
                        color="tab:green", capsize=2, label="after interferometry")
            ax.axhline(0, color="k", lw=0.8)
            ax.set_ylabel("mean count error ± 1 s.d. (targets per ping)")
        else:
            ax.plot(v, sw["count_after_mean"], "o-", ms=3, label="counted per ping")
            ax.set_ylabel("mean count per ping (targets)")
        derived = derived_in_sweep_units(ds)
        if derived is not None:
            ax.axvline(derived, color="tab:red", ls="--", label=f"derived threshold ({derived:.4g})")
        flat = plateau(ds)
        caption = ("Mean count error over the pings at every sweep point (bars: ±1 s.d. of one "
                   "ping); the dashed line is the scene's own threshold, derived from the noise "
                   "statistics, in the same units.")
        if flat is not None:
            ax.axvspan(flat[0], flat[1], color="tab:green", alpha=0.08,
                       label=f"plateau: |mean error after| ≤ {PLATEAU_TARGETS:g}")
            caption += (f" Plateau (mean error after interferometry within ±{PLATEAU_TARGETS:g} "
                        f"targets per ping): {flat[0]:.4g} to {flat[1]:.4g}")
            if derived is not None:
                caption += (f"; the derived threshold {derived:.4g} lies "
                            + ("on it." if flat[0] <= derived <= flat[1] else "OFF it."))
            else:
                caption += "."
        ax.set_xlabel(_sweep_axis_label(ds))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        figs.append(("Mean error vs the swept parameter (thesis Fig. 6.22)", save(fig, outdir / "sweep.png"),
                     caption))
        plt.close(fig)
    # density vs ping
    fig, ax = plt.subplots(figsize=(9, 4))
    if has_truth:
        ax.plot(ping, base["true_density_per_m3"], "k-", lw=1.3, label="true")
    ax.plot(ping, base["density_per_m3"], "-", color="tab:green", lw=1, label="counted (after interferometry)")
    ax.set_xlabel("ping index")
    ax.set_ylabel("density (targets per m³)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    figs.append(("Density per ping (thesis Fig. 6.25)", save(fig, outdir / "density.png"),
                 f"Counted density {float(base['density_per_m3'].mean()):.4f} m⁻³ on average"
                 + (f" (true {float(base['true_density_per_m3'].mean()):.4f} m⁻³)." if has_truth else ".")))
    plt.close(fig)
    # target strength from echo integration
    sv = base["s_v_per_m"].values
    if np.isfinite(sv).any():
        fig, ax = plt.subplots(figsize=(9, 4))
        with np.errstate(divide="ignore", invalid="ignore"):
            ts_ping = 10 * np.log10(base["sigma_bs_m2"].values)
        ax.plot(ping, ts_ping, ".", color="tab:blue", label="per ping: s_v / counted density")
        ts_est = float(ds["ts_estimate_db"].isel(setting=0))
        ax.axhline(ts_est, color="tab:blue", lw=1.5, label=f"over the run: {ts_est:.2f} dB")
        if has_truth:
            ts_true = float(ds["ts_true_db"].isel(setting=0))
            ax.axhline(ts_true, color="k", ls="--", label=f"true mean σ_bs: {ts_true:.2f} dB")
        ax.set_xlabel("ping index")
        ax.set_ylabel("TS = 10 log10 σ_bs (dB re 1 m²)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        figs.append(("Target strength from echo integration (thesis §1.4)", save(fig, outdir / "ts.png"),
                     "Echo integration of the calibrated image over the counting volume gives s_v; "
                     "divided by the counted density it gives the mean backscattering cross-section. "
                     "Single pings scatter widely (a few fish anywhere in the beam); the run's "
                     "estimate is Σ s_v / Σ n."))
        plt.close(fig)
    for p in sorted(outdir.glob("detections_ping*.png"), key=lambda q: int(q.stem[15:])):
        figs.append((f"Fan-beam image with detections, ping {p.stem[15:]} (thesis Appendix B)", p,
                     "Left: |I| (dB re the ping's peak) with the detections; middle and right: the "
                     "located detections and the true targets seen from above and from the side, "
                     "with the counting volume."))
    return figs


def _table(rows) -> str:
    return "<table>" + "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                               for r in rows) + "</table>"


def write_report(ds: xr.Dataset, out_dir) -> Path:
    """``out_dir/report.html`` (self-contained: images embedded) and ``out_dir/figures/*.png``.

    Parameters
    ----------
    ds : xarray.Dataset
        An experiment's results.
    out_dir : path

    Returns
    -------
    Path
        The report, written atomically.
    """
    out = Path(out_dir)
    figs = report_figures(ds, out / "figures")
    base = ds.isel(setting=0)
    has_truth = bool(np.isfinite(base["true_in_volume"].values).any())
    summary = [["pings", ds.sizes["ping"]], ["settings (scene + sweep points)", ds.sizes["setting"]]]
    units, mu_units, _ = threshold_units(ds)
    t_counts = float(np.nanmedian(base["threshold_counts"]))
    sig_med = float(np.nanmedian(base["noise_sigma_counts"])) if np.isfinite(base["noise_sigma_counts"]).any() else np.nan
    if mu_units is None or not sig_med > 0:
        summary.append(["threshold of the scene's setting (median, ADC counts)", f"{t_counts:.4g}"])
    else:
        t = t_counts / rayleigh_mean(sig_med) * mu_units
        name = {"noise_mean": "multiples of μ̂", "thesis": "thesis image units"}[units]
        summary.append([f"threshold of the scene's setting (median, {name}; ADC counts)",
                        f"{t:.4g} ({t_counts:.4g} ADC counts)"])
    if np.isfinite(base["noise_sigma_counts"]).any():
        sig = float(np.nanmedian(base["noise_sigma_counts"]))
        summary.append(["noise σ̂ / μ̂ (ADC counts)", f"{sig:.3f} / {rayleigh_mean(sig):.3f}"])
    if has_truth:
        for k in ("error_before", "error_after"):
            summary.append([f"{k.replace('_', ' ')} (mean ± s.d., targets per ping)",
                            f"{float(base[k].mean()):+.3f} ± {float(base[k].std()):.3f}"])
        summary.append(["true in volume per ping (mean)", f"{float(base['true_in_volume'].mean()):.3f}"])
    flat = plateau(ds)
    if flat is not None:
        derived = derived_in_sweep_units(ds)
        summary.append([f"plateau of the sweep (|mean error after| ≤ {PLATEAU_TARGETS:g})",
                        f"{flat[0]:.4g} to {flat[1]:.4g}" + (
                            f"; derived threshold {derived:.4g} " + ("on it" if flat[0] <= derived <= flat[1] else "OFF it")
                            if derived is not None else "")])
    summary.append(["counted density (mean, m⁻³)", f"{float(base['density_per_m3'].mean()):.5f}"])
    if np.isfinite(ds["ts_estimate_db"].isel(setting=0)):
        summary.append(["TS from s_v and counted density (dB re 1 m²)",
                        f"{float(ds['ts_estimate_db'].isel(setting=0)):.2f}"])
        if has_truth:
            summary.append(["true mean σ_bs in the volume (dB re 1 m²)",
                            f"{float(ds['ts_true_db'].isel(setting=0)):.2f}"])
    if "track_count_nmae" in ds:
        b = ds.isel(setting=0)
        summary.append([f"tracks over {ds.sizes['run']} run(s) of {int(ds.attrs.get('track_pings', 0))} "
                        "pings: passages counted / true", f"{int(np.nansum(b['run_counted_passages']))} / "
                        f"{int(np.nansum(b['run_true_passages']))}"])
        nm = float(b["track_count_nmae"])
        summary.append(["nMAE of the track counts over the runs (Σ|counted − true| / Σ true)",
                        f"{nm:.3f}" if np.isfinite(nm) else "– (no fish passed)"])
        summary.append(["HOTA, DetA, AssA, LocA, IDF1, MOTA (means over the runs with a fish or a track)",
                        ", ".join(f"{v:.3f}" if np.isfinite(v := float(b[f'{k}_mean'])) else "–"
                                  for k in ("hota", "deta", "assa", "loca", "idf1", "mota"))])
    timing = [["wall time (s)", f"{ds.attrs.get('wall_seconds', 0):.1f}"],
              ["workers", ds.attrs.get("workers", "")], ["scheduler", ds.attrs.get("scheduler", "")],
              ["tasks run / resumed", f"{ds.attrs.get('tasks_run', '')} / {ds.attrs.get('tasks_resumed', '')}"],
              ["task time, sum over pings (s)", f"{float(ds['task_seconds'].sum()):.1f}"]]
    timing += [[f"stage {k} (s, all pings)", f"{v:.2f}"] for k, v in json.loads(ds.attrs.get("stage_seconds_json", "{}")).items()]
    settings = json.loads(ds.attrs["settings_json"])[0]
    set_rows = [[k, json.dumps(v)] for k, v in settings.items()]
    parts = [f"<h1>{html.escape(ds.attrs.get('title', 'abacus experiment'))}</h1>",
             f"<p>Scene <code>{html.escape(ds.attrs.get('scene_file', ''))}</code>, sha256 "
             f"<code>{ds.attrs.get('scene_sha256', '')[:16]}</code>"
             + (f"; sweep <code>{html.escape(ds.attrs['sweep'])}</code>" if ds.attrs.get("sweep") else "")
             + ".</p>", "<h2>Summary</h2>", _table(summary)]
    for title, path, caption in figs:
        data = base64.b64encode(Path(path).read_bytes()).decode()
        parts.append(f"<h2>{html.escape(title)}</h2><figure><img alt=\"{html.escape(title)}\" "
                     f"src=\"data:image/png;base64,{data}\"><figcaption>{html.escape(caption)}"
                     f"</figcaption></figure>")
    parts += ["<h2>Processing settings (the scene's)</h2>", _table(set_rows),
              "<h2>Timing</h2>", _table(timing)]
    if ds.attrs.get("notes"):
        parts += ["<h2>Notes</h2>", f"<p>{html.escape(ds.attrs['notes'])}</p>"]
    page = ("<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>"
            + html.escape(ds.attrs.get("title", "abacus experiment")) + "</title><style>"
            "body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
            "img{max-width:100%;border:1px solid #ddd}table{border-collapse:collapse}"
            "td{border:1px solid #ccc;padding:3px 8px;font-size:0.9em}"
            "figcaption{font-size:0.9em;color:#555}code{background:#f4f4f4}"
            "</style></head><body>" + "\n".join(parts) + "</body></html>")
    path = out / "report.html"
    write_text_atomic(path, page)
    return path
