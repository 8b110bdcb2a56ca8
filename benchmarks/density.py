"""Counts against density: per-ping counts and track counts of a swimming school against the truth
at densities from sparse to beyond the thesis' (0.46 fish/m³, Tables 6.4 and 6.6), several seeds
each — the "Counting against density" section of docs/validation.md.

    python benchmarks/validation.py --only density
    python benchmarks/density.py            # the same section alone, printed

A school of swimbladder fish (6 × 1 cm) fills an ellipsoid 2.4 × 4 × 4 m around the fan of a
down-looking sonar, 17–21 m deep, at a number density ρ, and swims across the fan at 0.15 m/s
(loosely polarised, turning), 24 pings 0.25 s apart, physical levels and sea noise. The counting
volume is the transmit beam between 17.5 and 20.5 m, inside the school, so its true density is ρ.
Per ping: the count after interferometry against the true number in the volume; per run: the
tracks through the volume against the fish that passed through it (processing.track, default
settings); bias = Σ(counted − true) / Σ true and nMAE = Σ|counted − true| / Σ true (Kay et al.
2022), over pings (per-ping counts) or runs (track counts) of all seeds; HOTA and IDF1 as mean ±
standard deviation over the seeds.
"""
from __future__ import annotations

import time
import warnings

import numpy as np

try:
    from _report import ROOT, machine, table
except ImportError:        # run from the repository root
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).parent))
    from _report import ROOT, machine, table

THESIS_DENSITY = 0.46          # fish/m³, thesis Tables 6.4 and 6.6
DENSITIES = (0.1, 0.25, 0.46, 1.0, 2.0, 4.0, 8.0)
#: seeds reported: held out while count.coincidence_correction and count.volume_edge were built
#: and their defaults chosen
SEEDS = tuple(range(321, 331))
#: seeds the correction's and the soft edge's models and defaults were chosen on (and where
#: 301–305's misses were traced)
DEV_SEEDS = tuple(range(301, 321))
PINGS = 24
NMAE_LIMIT = 0.10
#: densities at which the per-ping count is also taken with ``detect.elevation: fit`` (a few fits
#: per detection: a minute per run at the thesis' density)
FIT_DENSITIES = (THESIS_DENSITY,)

SCENE = """
schema_version: 1
name: density-{rho}
description: A school at {rho} fish/m3 swimming across the fan, for the count-against-density curve.
seed: 1
sonar:
  pose: {{position_m: [0.0, 0.0, 1.0], boresight: [0.0, 0.0, 1.0], receiver_axis: [0.0, 1.0, 0.0]}}
  levels: {{source_level_db: 210.0}}
medium: {{temperature_c: 10.0, salinity_psu: 35.0, depth_m: 20.0}}
noise: {{enabled: true, model: sea}}
targets:
  populations:
    - kind: school
      center_m: [0.0, 0.0, 19.0]
      semi_axes_m: [1.2, 2.0, 2.0]
      heading_deg: 0
      density_per_m3: {rho}
      nearest_neighbour_m: 0.25
      redraw: false
      random_phase: true
      backscatter: {{model: swimbladder, length_m: 0.06, width_m: 0.01, tilt_sd_deg: 10.0}}
      swim: {{speed_m_s: 0.15, speed_sd_m_s: 0.02, heading_deg: 0, polarisation: 0.97,
             turn_sd_deg_per_s: 3.0, vertical_sd_m_s: 0.01}}
      label: school
pings: {{count: {pings}, interval_s: 0.25}}
processing:
  image: {{range_m: [14.5, 23.5]}}
  detect:
    method: rayleigh
    pfa_image: 1.0e-6
    noise: {{source: region, range_m: [14.5, 16.5], estimator: ml}}
  count: {{range_m: [17.5, 20.5]}}
"""


def _run(rho, seed):
    """Per-ping counted, per-ping true, track summary, per-ping reference count and per-ping
    count corrected for coincidence (count.coincidence_correction = poisson) of one run."""
    import acoustics
    import processing
    from acoustics.scene import scene_from_text
    from processing.base.contract import COUNTS_GROUP
    from processing.pipeline import RecordChain, resolve_settings
    from processing.tracking.tracks import track, track_summary
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = scene_from_text(SCENE.format(rho=rho, pings=PINGS))
        tree = processing.count(acoustics.simulate(scene, seed=seed))
        c = tree[COUNTS_GROUP].ds
        s = track_summary(track(tree))["summary"]
        # the reference count (count.sidelobe_db = ghost_db = 0: every detection located inside
        # counted)
        st = resolve_settings(tree)
        off = st.model_copy(update={"count": st.count.model_copy(update={"sidelobe_db": 0.0, "ghost_db": 0.0})})
        chain = RecordChain(tree, settings=off)
        ref = chain.count(chain.detected())[0]["count_after"].astype(float)
        # the count corrected for fish sharing a resolution cell (processing/detection/coincidence.py)
        poisson = st.model_copy(update={"count": st.count.model_copy(update={"coincidence_correction": "poisson"})})
        chain = RecordChain(tree, settings=poisson)
        corr = chain.count(chain.detected())[0]["count_corrected"].astype(float)
        # the soft counting-volume edge (processing/detection/volume_edge.py): σ the Cramér–Rao
        # bound from the SNR alone, and capped by a 30 dB signal-to-interference ratio (the
        # tracker's measured cap, a sensitivity check)
        soft = []
        for cap in (None, 30.0):
            edge = st.model_copy(update={"count": st.count.model_copy(
                update={"volume_edge": "soft", "edge_interference_db": cap})})
            chain = RecordChain(tree, settings=edge)
            soft.append(chain.count(chain.detected())[0]["count_expected"].astype(float))
        # the elevation from the two-target fit where a neighbour's echo merges with the fish's
        # (processing/detection/elevation_fit.py): detected again
        fit = None
        if rho in FIT_DENSITIES:
            elev = st.model_copy(update={"detect": st.detect.model_copy(update={"elevation": "fit"})})
            chain = RecordChain(tree, settings=elev)
            fit = chain.count(chain.detect())[0]["count_after"].astype(float)
    return (c["count_after"].values.astype(float), c["true_in_volume"].values.astype(float), s, ref, corr,
            soft[0], soft[1], fit)


def _coefficient(rho=THESIS_DENSITY, seed=SEEDS[0]):
    """The coincidence coefficient a of the benchmark's counting volume and resolution."""
    import acoustics
    import processing
    from acoustics.scene import scene_from_text
    from processing.detection.coincidence import coincidence_coefficient
    from processing.pipeline import RecordChain
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = processing.count(acoustics.simulate(scene_from_text(SCENE.format(rho=rho, pings=1)), seed=seed))
        chain = RecordChain(tree)
        d = chain.detected()
        return coincidence_coefficient(d.volume, range_resolution_m=d.range_resolution_m,
                                       azimuth_resolution_rad=d.azimuth_resolution_rad,
                                       unresolved_cells=chain.settings.count.unresolved_cells)


def density_curve(densities=DENSITIES, seeds=SEEDS):
    """Rows of the curve: one dict per density."""
    out = []
    for rho in densities:
        pc, pt, runs, pr, pk, ps, ps30, pf = [], [], [], [], [], [], [], []
        t0 = time.perf_counter()
        for seed in seeds:
            c, t, s, ref, corr, soft, soft30, fit = _run(rho, seed)
            pf.append(fit)
            ps.append(soft)
            ps30.append(soft30)
            pr.append(ref)
            pk.append(corr)
            pc.append(c)
            pt.append(t)
            runs.append(s)
        # per run (Kay et al. 2022's clip): the run's summed per-ping count, its density estimate
        run_c, run_k, run_t, run_s, run_s30 = (np.array([x.sum() for x in v]) for v in (pc, pk, pt, ps, ps30))
        fitted = {}
        if all(f is not None for f in pf):
            fit_seed = np.array([np.abs(f - t_).sum() / t_.sum() if t_.sum() else np.nan for f, t_ in zip(pf, pt)])
            run_f = np.array([f.sum() for f in pf])
            pf_, pt_ = np.concatenate(pf), np.concatenate(pt)
            fitted = {"fit_bias": float((pf_ - pt_).sum() / pt_.sum()),
                      "fit_nmae": float(np.abs(pf_ - pt_).sum() / pt_.sum()),
                      "fit_nmae_sd": float(np.nanstd(fit_seed, ddof=1)),
                      "fit_run_nmae": float(np.abs(run_f - run_t).sum() / run_t.sum()),
                      "fit_abs": int(np.abs(pf_ - pt_).sum()),
                      "ping_abs": int(np.abs(np.concatenate(pc) - pt_).sum()),
                      "true_total": int(pt_.sum())}
        pc, pt, pr, pk = np.concatenate(pc), np.concatenate(pt), np.concatenate(pr), np.concatenate(pk)
        ps, ps30 = np.concatenate(ps), np.concatenate(ps30)
        soft_seed = np.array([np.abs(c_ - t_).sum() / t_.sum() if t_.sum() else np.nan
                              for c_, t_ in zip(np.split(ps, len(seeds)), np.split(pt, len(seeds)))])
        tc = np.array([r["track_count"] for r in runs], float)
        tt = np.array([r["true_passages"] for r in runs], float)
        seed_nmae = [abs(a - b) / b for a, b in zip(tc, tt) if b > 0]
        ping_seed = np.array([np.abs(c_ - t_).sum() / t_.sum() if t_.sum() else np.nan
                              for c_, t_ in zip(np.split(pc, len(seeds)), np.split(pt, len(seeds)))])
        # a run with no fish and no track in the volume has no score (TrackEval's HOTA reads 0
        # there): left out of the means
        scored = [r.get("true_passages", 0) > 0 or r["track_count"] > 0 for r in runs]
        hota = np.array([r["hota"] if r["hota"] is not None and ok else np.nan for r, ok in zip(runs, scored)], float)
        idf1 = np.array([r["idf1"] if r["idf1"] is not None and ok else np.nan for r, ok in zip(runs, scored)], float)
        out.append({"rho": rho, "true_per_ping": float(pt.mean()), "counted_per_ping": float(pc.mean()),
                    "ping_bias": float((pc - pt).sum() / pt.sum()), "ping_nmae": float(np.abs(pc - pt).sum() / pt.sum()),
                    "ping_nmae_sd": float(np.nanstd(ping_seed, ddof=1)),
                    "ref_bias": float((pr - pt).sum() / pt.sum()), "ref_nmae": float(np.abs(pr - pt).sum() / pt.sum()),
                    "corr_bias": float((pk - pt).sum() / pt.sum()), "corr_nmae": float(np.abs(pk - pt).sum() / pt.sum()),
                    "soft_bias": float((ps - pt).sum() / pt.sum()), "soft_nmae": float(np.abs(ps - pt).sum() / pt.sum()),
                    "soft_nmae_sd": float(np.nanstd(soft_seed, ddof=1)),
                    "soft_run_nmae": float(np.abs(run_s - run_t).sum() / run_t.sum()),
                    "soft30_bias": float((ps30 - pt).sum() / pt.sum()),
                    "soft30_nmae": float(np.abs(ps30 - pt).sum() / pt.sum()),
                    "soft30_run_nmae": float(np.abs(run_s30 - run_t).sum() / run_t.sum()),
                    "soft_changed_pings": int(np.sum(np.abs(ps - pc) > 0.01)),
                    "run_nmae": float(np.abs(run_c - run_t).sum() / run_t.sum()),
                    "corr_run_nmae": float(np.abs(run_k - run_t).sum() / run_t.sum()),
                    "true_passages": int(tt.sum()), "tracks": int(tc.sum()),
                    "track_bias": float((tc - tt).sum() / tt.sum()), "track_nmae": float(np.abs(tc - tt).sum() / tt.sum()),
                    "track_nmae_sd": float(np.std(seed_nmae, ddof=1)) if len(seed_nmae) > 1 else float("nan"),
                    "hota": float(np.nanmean(hota)), "hota_sd": float(np.nanstd(hota, ddof=1)),
                    "idf1": float(np.nanmean(idf1)), "idf1_sd": float(np.nanstd(idf1, ddof=1)),
                    "seconds": time.perf_counter() - t0, **fitted})
        print(f"  ρ = {rho}: {out[-1]['seconds']:.0f} s", flush=True)
    return out


def _crossing(rows, key):
    """The lowest density at which ``key`` passes NMAE_LIMIT (linear interpolation between the
    densities around the first crossing), or None."""
    for a, b in zip(rows, rows[1:]):
        if a[key] <= NMAE_LIMIT < b[key]:
            f = (NMAE_LIMIT - a[key]) / (b[key] - a[key])
            return float(np.exp(np.log(a["rho"]) + f * (np.log(b["rho"]) - np.log(a["rho"]))))
    return None


def _figure(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rho = np.array([r["rho"] for r in rows])
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.2), constrained_layout=True)
    ax = axes[0]
    for key, label, m, col in (("ping", "per-ping count", "s", "tab:blue"), ("track", "track count", "o", "tab:green")):
        ax.errorbar(rho, [100 * r[f"{key}_nmae"] for r in rows], yerr=[100 * r[f"{key}_nmae_sd"] for r in rows],
                    fmt=m + "-", color=col, ms=4, capsize=3, label=f"nMAE, {label}")
        ax.plot(rho, [100 * r[f"{key}_bias"] for r in rows], m + "--", color=col, ms=4, mfc="none",
                label=f"bias, {label}")
    ax.plot(rho, [100 * r["ref_bias"] for r in rows], "x:", color="grey", ms=5,
            label="bias, per-ping count, reference (every detection counted)")
    ax.plot(rho, [100 * r["corr_bias"] for r in rows], "d-.", color="tab:purple", ms=4,
            label="bias, per-ping count, coincidence-corrected (poisson)")
    ax.plot(rho, [100 * r["soft_nmae"] for r in rows], "v:", color="tab:orange", ms=4,
            label="nMAE, per-ping count, soft volume edge")
    fr = [r for r in rows if "fit_nmae" in r]
    # set a little to the right of the per-ping count's own point, which it would hide
    ax.errorbar([1.08 * r["rho"] for r in fr], [100 * r["fit_nmae"] for r in fr],
                yerr=[100 * r["fit_nmae_sd"] for r in fr], fmt="*", color="black", ms=9, capsize=3,
                label="nMAE, per-ping count, elevation fit (drawn 8 % right)")
    # the reference per-ping count's sidelobes reach hundreds of per cent: linear within ±10 %, log beyond
    ax.set_yscale("symlog", linthresh=10)
    ax.axhline(100 * NMAE_LIMIT, color="k", lw=0.8, ls=":", label="nMAE 10 %")
    ax.axhline(0, color="grey", lw=0.6)
    ax.axvline(THESIS_DENSITY, color="tab:red", lw=0.8, ls="-.", label="thesis' density 0.46 m⁻³")
    ax.set_xscale("log")
    ax.set_xlabel("true density in the counting volume ρ (fish/m³)")
    ax.set_ylabel("count error (% of the true count; symlog)")
    ax.set_title("counts against density (error bars: s.d. over seeds)")
    # below the axes: inside, it hides the bias curves
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=2)
    ax.grid(alpha=0.3, which="both")
    ax = axes[1]
    for key, label, m in (("hota", "HOTA", "o"), ("idf1", "IDF1", "s")):
        ax.errorbar(rho, [r[key] for r in rows], yerr=[r[f"{key}_sd"] for r in rows], fmt=m + "-", ms=4,
                    capsize=3, label=label)
    ax.axvline(THESIS_DENSITY, color="tab:red", lw=0.8, ls="-.")
    ax.set_xscale("log")
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("true density in the counting volume ρ (fish/m³)")
    ax.set_ylabel("score (mean ± s.d. over seeds)")
    ax.set_title("tracking scores against density")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=2)
    ax.grid(alpha=0.3, which="both")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def density_section() -> str:
    t0 = time.perf_counter()
    rows = density_curve()
    seconds = time.perf_counter() - t0
    fig = ROOT / "docs" / "figures" / "count_vs_density.png"
    _figure(rows, fig)
    body = [[f"{r['rho']:g}", f"{r['true_per_ping']:.2f}", f"{r['counted_per_ping']:.2f}",
             f"{100 * r['ping_bias']:+.1f}", f"{100 * r['ping_nmae']:.1f} ± {100 * r['ping_nmae_sd']:.1f}",
             f"{100 * r['ref_bias']:+.1f} / {100 * r['ref_nmae']:.1f}",
             f"{100 * r['corr_bias']:+.1f} / {100 * r['corr_nmae']:.1f}",
             f"{100 * r['run_nmae']:.1f} / {100 * r['corr_run_nmae']:.1f}",
             f"{100 * r['soft_bias']:+.1f} / {100 * r['soft_nmae']:.1f} / {100 * r['soft_run_nmae']:.1f}",
             (f"{100 * r['fit_bias']:+.1f} / {100 * r['fit_nmae']:.1f} ± {100 * r['fit_nmae_sd']:.1f} / "
              f"{100 * r['fit_run_nmae']:.1f}" if "fit_bias" in r else "–"),
             f"{r['tracks']} / {r['true_passages']}", f"{100 * r['track_bias']:+.1f}",
             f"{100 * r['track_nmae']:.1f} ± {100 * r['track_nmae_sd']:.1f}",
             f"{r['hota']:.3f} ± {r['hota_sd']:.3f}", f"{r['idf1']:.3f} ± {r['idf1_sd']:.3f}"] for r in rows]
    thesis = next(r for r in rows if r["rho"] == THESIS_DENSITY)
    cross_t, cross_p = _crossing(rows, "track_nmae"), _crossing(rows, "ping_nmae")

    def where(x, key):
        if x is not None:
            return f"passes 10 % near **ρ ≈ {x:.2g} fish/m³**"
        if all(r[key] <= NMAE_LIMIT for r in rows):
            return f"stays within 10 % up to ρ = {rows[-1]['rho']:g} fish/m³, the densest run"
        return "is beyond 10 % already at the sparsest density" if rows[0][key] > NMAE_LIMIT else \
            "crosses 10 % more than once (see the table)"
    ok_bias = abs(thesis["track_bias"]) <= 0.05
    ok_nmae = thesis["track_nmae"] <= 0.05
    ok_ping = abs(thesis["ping_bias"]) <= 0.05 and thesis["ping_nmae"] <= 0.05
    ok_run = abs(thesis["ping_bias"]) <= 0.05 and thesis["run_nmae"] <= 0.05
    ok_corr = abs(thesis["corr_bias"]) <= 0.05 and thesis["corr_nmae"] <= 0.05
    ok_corr_run = abs(thesis["corr_bias"]) <= 0.05 and thesis["corr_run_nmae"] <= 0.05
    ok_soft = abs(thesis["soft_bias"]) <= 0.05 and thesis["soft_nmae"] <= 0.05
    ok_fit = abs(thesis["fit_bias"]) <= 0.05 and thesis["fit_nmae"] <= 0.05
    ok_fit_run = abs(thesis["fit_bias"]) <= 0.05 and thesis["fit_run_nmae"] <= 0.05
    coef = _coefficient()
    verdict = (lambda ok: "met" if ok else "**not met**")
    return (
        "## Counting against density (issue 29)\n\n"
        "Field counts agree with the truth at typical densities and fall below it as density "
        "rises, because targets are no longer resolved (Enzenhofer et al. 1998); here the curve "
        "with true identities. `python benchmarks/validation.py --only density` "
        "(benchmarks/density.py): a school of swimbladder fish (6 × 1 cm, fish ≥ 0.25 m apart) "
        "fills an ellipsoid 2.4 × 4 × 4 m around the fan of a down-looking sonar, 17–21 m deep, "
        f"at density ρ, and swims across the fan at 0.15 m/s; {PINGS} pings 0.25 s apart, "
        "physical levels and sea noise; the counting volume is the transmit beam from 17.5 to "
        f"20.5 m, inside the school. {len(DENSITIES)} densities × {len(SEEDS)} seeds "
        f"({SEEDS[0]}–{SEEDS[-1]}, held out: never used while `count.coincidence_correction` and "
        f"`count.volume_edge` were built; their models and defaults were chosen on seeds "
        f"{DEV_SEEDS[0]}–{DEV_SEEDS[-1]}), "
        "default settings throughout. *Per-ping*: the count after "
        "interferometry against the true number in the volume, with the default sidelobe and ghost "
        "rules (processing/detection/sidelobes.py: a detection in the range or azimuth response of a "
        "detection more than `count.sidelobe_db` = 30 dB stronger in its ping, or at its range and "
        "ghost azimuth no more than `count.ghost_db` = 6 dB above the ghost level its elevation "
        "predicts, is not counted) and without them (the *reference*, both 0: every detection "
        "located inside counted); bias = Σ(counted − true) / Σ "
        "true and nMAE = Σ|counted − true| / Σ true over all pings of all seeds (± the standard "
        "deviation of the per-seed nMAE); *tracks*: tracks through the volume against the fish "
        "that passed through it, the same over the runs (± s.d. of the per-run |error| / true); "
        "*coincidence-corrected*: the per-ping count with `count.coincidence_correction: poisson` "
        "(processing/detection/coincidence.py: N̂ = −W₀(−aD)/a, the expected number of fish behind "
        "D echoes when fish spread uniformly and two within `count.unresolved_cells` = 1.5 "
        f"resolution cells give one echo; here a = {coef:.4f} per fish in the volume); *soft edge*: "
        "the per-ping count with `count.volume_edge: soft` (processing/detection/volume_edge.py: "
        "each counted detection weighs the probability Φ((φ_h − φ̂)/σ) − Φ((−φ_h − φ̂)/σ) that "
        "its fish lies inside the fan's elevation faces ±φ_h, σ the Cramér–Rao bound of its "
        "located elevation φ̂ from its SNR, the baseline and the wavelength; the expected number "
        "of fish inside); *per-run "
        "nMAE*: Σ|Σ counted − Σ true| / Σ true over the runs, each run's summed per-ping count "
        "(its density estimate) as Kay et al.'s clip, so the errors of single runs do not cancel "
        "but those of single pings within a run do; "
        "HOTA and IDF1 mean ± s.d. over the seeds (a run with no fish and no track in the volume, "
        "whose scores are undefined, left out). The single-scattering limit of docs/scenes.md "
        "(τ = n σ_e L ≤ 0.1) is at ρ ≈ 27 fish/m³ through this school's 4 m depth, beyond the "
        f"densest run here. Run time {seconds:.0f} s ({machine()}).\n\n"
        + table(["ρ (fish/m³)", "true per ping", "counted per ping", "per-ping bias (%)", "per-ping nMAE (%)",
                 "per-ping bias / nMAE, reference (%)", "per-ping bias / nMAE, coincidence-corrected (%)",
                 "per-run nMAE of the per-ping count, as is / corrected (%)",
                 "soft edge: per-ping bias / nMAE / per-run nMAE (%)",
                 "elevation fit: per-ping bias / nMAE / per-run nMAE (%)", "tracks / true passages", "track bias (%)", "track nMAE (%)", "HOTA", "IDF1"], body)
        + "\n\n![counts and scores against density](figures/count_vs_density.png)\n\n"
        f"**At the thesis' density (0.46 fish/m³)** the track count's bias is "
        f"{100 * thesis['track_bias']:+.1f} % and its nMAE {100 * thesis['track_nmae']:.1f} % "
        f"(issue 29's target: both within 5 % — {'met' if ok_bias and ok_nmae else '**not met**'}); the "
        f"per-ping count's bias {100 * thesis['ping_bias']:+.1f} %, nMAE over pings "
        f"{100 * thesis['ping_nmae']:.1f} % ({verdict(ok_ping)}) and over runs "
        f"{100 * thesis['run_nmae']:.1f} % ({verdict(ok_run)}; the reference "
        f"{100 * thesis['ref_bias']:+.1f} % and {100 * thesis['ref_nmae']:.1f} %); coincidence-corrected, "
        f"bias {100 * thesis['corr_bias']:+.1f} %, nMAE over pings {100 * thesis['corr_nmae']:.1f} % "
        f"({verdict(ok_corr)}) and over runs {100 * thesis['corr_run_nmae']:.1f} % ({verdict(ok_corr_run)}); "
        f"with the soft volume edge, bias {100 * thesis['soft_bias']:+.1f} %, nMAE over pings "
        f"{100 * thesis['soft_nmae']:.1f} % ({verdict(ok_soft)}) and over runs "
        f"{100 * thesis['soft_run_nmae']:.1f} % ({thesis['soft_changed_pings']} of the "
        f"{len(SEEDS) * PINGS} pings changed by more than 0.01 fish); with the elevation of a "
        f"merged echo from the two-target fit (`detect.elevation: fit`, below), bias "
        f"{100 * thesis['fit_bias']:+.1f} %, nMAE over pings {100 * thesis['fit_nmae']:.1f} % "
        f"({verdict(ok_fit)}; {thesis['fit_abs']} of the {thesis['true_total']} fish-pings in error, against "
        f"{thesis['ping_abs']} with the peak's phase) and over runs {100 * thesis['fit_run_nmae']:.1f} % "
        f"({verdict(ok_fit_run)}). "
        f"The track count's nMAE {where(cross_t, 'track_nmae')}; the per-ping count's "
        f"{where(cross_p, 'ping_nmae')}. Few fish pass at the sparsest densities (a handful per "
        "run), so there one fish more or less is tens of per cent: read the low end's nMAE with "
        "its spread."
        + (" The reference over-counts the sparse schools: at physical levels (a fish on axis "
           "80–90 dB above the noise) the range sidelobes of a strong fish in its own beam (−40 to "
           "−50 dB within a few range cells, −70 to −80 dB out to the 7 ms pulse's 5 m) and the "
           "stagger ghosts of fish beside the fan in elevation (at sin θ ± λ/(2d), 15–20 dB down "
           "for a fish 2° off the fan) pass the detector, and interferometry places some of them "
           "inside the volume. Found against the truth on seeds 301–305: every false count of the "
           "reference at 0.1 and 0.46 fish/m³ lay in the range response of a detection 40–75 dB "
           "stronger or at the ghost azimuth of one; the rules remove all of them and no detection "
           "of a real fish at these densities (the misses with and without them are the same). "
           "What the per-ping count still misses at 0.46 fish/m³ are pairs of fish at one range "
           "closer in azimuth than its resolution (2.4°): one echo for two (on seeds 301–305 all 12 "
           "missed fish-pings of the 136 had another fish within 1.22 resolution cells, and all were "
           "in one seed, 304, whose pairs stay unresolved for most of its pings: the −8.8 % of "
           "those five seeds; on the 20 development seeds 301–320 the bias is −4.0 %). As density rises, such shared cells "
           "dominate (the thesis' undercount of dense regions, §6.3.2): both counts fall below "
           "the truth, the field's picture (Enzenhofer et al. 1998). The tracker's single-target "
           "rules and M-of-N confirmation keep sidelobes and ghosts out of the tracks either way."
           if rows[0]["ref_bias"] > 0.2 else "")
        + "\n\n**The coincidence correction and its default.** Chosen on the development seeds "
        "301–320 (`python benchmarks/density.py --dev`, the per-ping count as is → corrected): at "
        "0.46 fish/m³ the bias −4.0 % → −0.7 % but the nMAE over pings 7.0 % → 10.0 % and over "
        "runs 6.2 % → 7.7 %; at 1 fish/m³ −5.1 % → +0.5 %, 11.2 % → 14.7 %, 7.1 % → 7.7 %; at 2, "
        "−11.6 % → −3.2 %, 16.2 % → 18.7 %, 11.8 % → 7.9 %; at 4, −23.1 % → −11.6 %, 26.2 % → 23.5 %, "
        "23.1 % → 15.4 %. So the default is `none`: at and below 1 fish/m³ the correction's gain "
        "in bias is smaller than the error it adds (a fraction of a fish on every ping, the many "
        "without a loss too), and from 2 fish/m³ it pays for a density estimate (bias, per-run "
        "nMAE); it does not make the per-ping nMAE (a mean correction cannot say which ping lost "
        "a fish). Why the low end is not a matter of the mean: on seeds 301–305 at 0.46 fish/m³ a "
        "fish with another within 1.5 cells in the fan was missed 42 % of the time (the model's "
        "one half per pair), but 19 % of the fish had such a neighbour against the 5 % of "
        "uniformly spread fish — in a polarised school, pairs swim side by side for many pings, "
        "so the losses come in runs of one seed, and a few seeds' bias is far from the mean. At 4 "
        "fish/m³ and beyond, part of the loss has no neighbour within the cell (a merged echo's "
        "elevation drags the located fish out of the volume, fish beside the fan merge with fish "
        "in it), which the model does not hold: the corrected count stays below the truth there. "
        "What else the per-ping nMAE holds at 0.46 fish/m³ (development seeds 301–320: 454 "
        "fish-pings, 25 missed, 7 counted falsely): every false count was a fish just beside the "
        "fan (0.44–0.94° off its axis, the volume's face at 0.42°) located inside it by its "
        "interferometric elevation — the thin fan's face, where a located elevation's error "
        "moves a fish in or out, costs nMAE but cancels in the bias."
        "\n\n**The soft volume edge and its default.** The idea: count each detection with the "
        "probability that its fish is inside given its located elevation and that elevation's σ, "
        "so that the count is the expected number of fish inside. It is the posterior mean of "
        "\"inside\" under a flat prior across the face, so it has the least *squared* error, 1/√2 "
        "of the hard count's per fish near a face; but the nMAE is a sum of *absolute* errors, "
        "and for those the hard decision (the posterior median) is the best one: the soft count's "
        "mean absolute error per fish near a face is √2 times the hard count's "
        "(tests/test_count_edge.py checks all three against synthetic fish). It can pay only "
        "where many fish per ping lie near a face, so that their errors add before the absolute "
        "value is taken. Chosen on the development seeds 301–320 "
        "(`python benchmarks/density.py --dev`; hard → soft, bias / nMAE over pings / nMAE over "
        "runs): at 0.46 fish/m³ −4.0 / 7.1 / 6.2 % → −4.6 / 9.6 / 6.9 % (70 of the 480 pings "
        "changed by more than 0.01 fish); at 1 fish/m³ −5.1 / 11.2 / 7.1 % → −4.6 / 15.2 / 6.9 %; "
        "at 2, −11.6 / 16.2 / 11.8 % → −11.0 / 18.4 / 11.3 %; at 4, −23.1 / 26.2 / 23.1 % → "
        "−24.3 / 27.5 / 24.5 %; with σ capped by a 30 dB signal-to-interference ratio (the "
        "tracker's, `count.edge_interference_db: 30`) the nMAE over pings is worse still (13.6 % at "
        "0.46 fish/m³). So the default stays `hard`. Why σ does not describe this scene's edge "
        "errors either (matched detections of seeds 301–302 at 0.46 fish/m³ within 1.5° of the "
        "fan): the detections' `snr_db` reads low against their elevation scatter — below 40 dB "
        "the located elevations scatter 0.13× the σ their SNR predicts, at 40–50 dB 0.5× "
        "(not traced; the noise region in front of the school, 14.5–16.5 m, lies within the range "
        "sidelobes of the school's 7 ms echoes), so the soft edge gives fractions of a fish to detections whose side of the "
        "face is not in doubt; above 70 dB the predicted σ (< 0.001°) is below a common −0.003° "
        "offset of the located elevations; and the false counts of the hard edge are fish up to "
        "0.5° beside the fan, whose elevation a neighbour's merged echo dragged (0.17° for one "
        "there), a heavy tail no Gaussian σ from the SNR holds. The per-ping nMAE at the thesis' "
        "density is therefore not reached by a soft edge: it is held by the shared-cell misses "
        "(25 missed fish-pings against 7 false counts on the development seeds) and by merged "
        "echoes."
        "\n\n"
        "**Why the false counts' elevations are wrong, and the elevation fit.** Traced on the "
        "development seeds 301–320 at 0.46 fish/m³ (`python benchmarks/density_edge.py`, the "
        "section below: the pings recounted with each estimator of ψ_AB): the 7 false counts are "
        "fish 0.44–0.94° off the fan's axis, detected 57–83 dB above the noise (the Cramér–Rao σ of "
        "their elevation is below 0.01°), none with a clipped elevation, located 0.03–0.89° nearer "
        "the axis than they are; each has another fish 0.84–1.37 resolution cells away, and its "
        "echo does not fit one point response (a one-target fit to the A and B images leaves −8 to "
        "−19 dB of the patch's energy, an isolated fish −40 to −47 dB). The two echoes merge and "
        "ψ_AB at the peak is the phase of their sum: glint, coherent over the echo. So averaging "
        "the phase over the echo (the amplitude-weighted mean phase difference of split-beam "
        "echosounders, Σ I_A I_B* over ±2 and ±8 interpolated samples, up to half the 3 dB range "
        "cell) moves them by less than 0.04° (nMAE over pings 7.05 → 7.05 and 7.93 %), and a "
        "one-target fit over the patch, which takes in more of the neighbour, is worse (11.0 %). "
        "What separates them is a model with two targets: `detect.elevation: fit` "
        "(processing/detection/elevation_fit.py) fits two point responses (the compressed pulse × "
        "the weighted subarray's array factor, both from the record) to the A and B images where "
        "one leaves more than −30 dB and two lower it by 6 dB, for detections 30 dB or more above "
        "the noise, and takes the phase, azimuth and range of the component nearest the peak. On "
        "the development seeds it locates 4 of the 7 at their true elevation (within 0.01°) and so "
        "outside, fails on the three of seed 317 (pings 10 and 22, where three fish share the "
        "patch, and ping 9, whose nearest component lies outside the fitted patch and is not "
        "taken: an extrapolation, which at ping 12 of that seed made a false count), "
        "adds one false count in that seed, and brings 3 missed fish back inside: bias −4.0 % → −4.0 %, "
        "nMAE over pings 7.05 → 5.73 % (missed fish-pings 25 → 22, false counts 7 → 4). On the "
        "held-out seeds (the table and the verdict above) it takes one fish-ping off the errors "
        "at 0.46 fish/m³, and that puts the nMAE at the 5 % line: a margin of one fish-ping, "
        "smaller than the spread between seeds. The default stays `peak` "
        "(the reference): the fit costs about a minute per run at this density on this machine (a "
        "few Levenberg–Marquardt fits per detection above 30 dB SNR) against under a second for "
        "detection, it moves the located positions the tracker uses (its effect on the tracks is "
        "not measured here), and what it leaves of the per-ping nMAE is the fish sharing a cell at "
        "one range, whose one echo it does not split into two counts."
        )


def development_rows(densities=(0.46, 1.0, 2.0, 4.0)):
    """The per-ping counts on the development seeds, as is and coincidence-corrected: what the
    correction's default was chosen on (``python benchmarks/density.py --dev``)."""
    rows = density_curve(densities, DEV_SEEDS)
    return table(["ρ (fish/m³)", "true per ping", "per-ping bias / nMAE (%)", "corrected (%)",
                  "per-run nMAE, as is / corrected (%)", "soft edge: bias / nMAE / per-run nMAE (%)",
                  "soft edge, 30 dB SIR cap: bias / nMAE / per-run nMAE (%)",
                  "pings the soft edge changes by > 0.01", "elevation fit: bias / nMAE / per-run nMAE (%)"],
                 [[f"{r['rho']:g}", f"{r['true_per_ping']:.2f}",
                   f"{100 * r['ping_bias']:+.1f} / {100 * r['ping_nmae']:.1f}",
                   f"{100 * r['corr_bias']:+.1f} / {100 * r['corr_nmae']:.1f}",
                   f"{100 * r['run_nmae']:.1f} / {100 * r['corr_run_nmae']:.1f}",
                   f"{100 * r['soft_bias']:+.2f} / {100 * r['soft_nmae']:.2f} / {100 * r['soft_run_nmae']:.2f}",
                   f"{100 * r['soft30_bias']:+.2f} / {100 * r['soft30_nmae']:.2f} / {100 * r['soft30_run_nmae']:.2f}",
                   f"{r['soft_changed_pings']}",
                   (f"{100 * r['fit_bias']:+.2f} / {100 * r['fit_nmae']:.2f} / {100 * r['fit_run_nmae']:.2f}"
                    if "fit_bias" in r else "–")] for r in rows])


if __name__ == "__main__":
    import sys as _sys
    print(development_rows() if "--dev" in _sys.argv else density_section())
