"""Tracking scored against the truth on scenes/school_tracks.yaml, with sweeps of the tracker's
decision rules: the "Tracking" section of docs/validation.md.

    python benchmarks/validation.py --only tracking

The scene is simulated with seeds never used while the tracker was developed (it was tuned on
1501, 1–3 and checked on 11–16); each run is detected and counted once, then tracked under every
setting, so a sweep compares settings on identical detections.
"""
from __future__ import annotations

import time
import warnings

import numpy as np
from _report import ROOT, table

SEEDS = (201, 202, 203, 204, 205, 206)
#: (setting, values) swept one at a time around the defaults
SWEEPS = (("gate_probability", (0.9, 0.99, 0.999)),
          ("method", ("kalman", "alpha_beta")),
          (("confirm_hits", "confirm_window"), ((2, 3), (3, 4), (4, 5))),
          ("accel_sd_m_s2", (0.03, 0.1, 0.3, 1.0)),
          ("interference_db", (15.0, 20.0, 30.0, 40.0)),
          ("min_ts_db", (-200.0, -70.0)),
          ("sidelobe_db", (0.0, 20.0)))


def _runs():
    import acoustics
    import processing
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = acoustics.load_scene(ROOT / "scenes" / "school_tracks.yaml")
        for seed in SEEDS:
            out.append(processing.count(acoustics.simulate(scene, seed=seed)))
    return scene, out


def _score(trees, settings):
    from processing.tracking.tracks import track, track_summary
    rows, t = [], 0.0
    for tree in trees:
        t0 = time.perf_counter()
        s = track_summary(track(tree, settings))["summary"]
        t += time.perf_counter() - t0
        rows.append(s)
    return rows, t / len(trees)


def _totals(rows):
    n_tr = sum(r["track_count"] for r in rows)
    n_true = sum(r["true_passages"] for r in rows)
    idf1 = [r["idf1"] for r in rows]
    return n_tr, n_true, 100.0 * (n_tr - n_true) / n_true, float(np.mean(idf1)), float(np.min(idf1))


def tracking_section() -> str:
    import processing
    from processing.settings import TrackSettings
    from abacus.figures.tracks import track_figures
    from processing.tracking.tracks import track
    scene, trees = _runs()
    base = processing.resolve_settings(trees[0], None)

    def with_track(**kw):
        return base.model_copy(update={"track": TrackSettings(**kw)})

    rows, t_default = _score(trees, with_track())
    per_seed = []
    for seed, r in zip(SEEDS, rows):
        per_seed.append([seed, r["true_passages"], r["track_count"], f"{r['track_count_error']:+d}",
                         f"{r['idf1']:.3f}", f"{r['mota']:.3f}", f"{100 * r['motp']:.1f}",
                         r["num_switches"], r["num_fragmentations"],
                         f"{r['speed_error_mean']:+.3f} ± {r['speed_error_sd']:.3f}",
                         f"{r['ts_error_mean']:+.2f} ± {r['ts_error_sd']:.2f}",
                         f"{r['track_density_per_m3']:.3f}", f"{r['true_density_per_m3']:.3f}",
                         f"{r['per_ping_density_per_m3']:.3f}"])
    n_tr, n_true, err, idf1_mean, idf1_min = _totals(rows)
    sweep_rows = []
    for key, values in SWEEPS:
        for v in values:
            kw = dict(zip(key, v)) if isinstance(key, tuple) else {key: v}
            r, t = _score(trees, with_track(**kw))
            a, b, e, m, lo = _totals(r)
            label = ", ".join(f"{k} = {x}" for k, x in kw.items())
            default = all(getattr(TrackSettings(), k) == x for k, x in kw.items())
            sweep_rows.append([label + (" (default)" if default else ""), a, b, f"{e:+.1f}", f"{m:.3f}",
                               f"{lo:.3f}", sum(x["num_switches"] for x in r),
                               f"{np.mean([x['speed_error_sd'] for x in r]):.3f}", f"{t:.2f}"])
    fig_dir = ROOT / "docs" / "figures"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        paths = track_figures(track(trees[0], with_track()), fig_dir / "tracking_tmp")
    for p in paths:
        p.replace(fig_dir / f"school_tracks_{p.name}")
    (fig_dir / "tracking_tmp").rmdir()
    sc = scene
    return (
        "## Tracking (issue 15)\n\n"
        f"`scenes/school_tracks.yaml`: {sc.targets.populations[0].count} swimbladder fish (6 × 1 cm, "
        f"TS ≈ −46…−37 dB) in a loose school 17–20 m below a sonar looking straight down, swimming "
        f"at 0.15 m/s across the 0.84° elevation fan, {sc.pings.count} pings {sc.pings.interval_s} s "
        "apart, physical levels (source level 210 dB, sea noise): a fish on axis is 80–90 dB above "
        "the noise. Tracks (`processing.track`, default settings) are scored inside the counting "
        "volume by py-motmetrics; a passage is a fish (true) or a track (counted) ever inside the "
        f"volume. Seeds {SEEDS[0]}–{SEEDS[-1]} were never used while the tracker was built.\n\n"
        f"**Track-based count: {n_tr} tracks for {n_true} true passages over the {len(SEEDS)} runs "
        f"({err:+.1f} %); IDF1 {idf1_mean:.3f} on average, {idf1_min:.3f} at worst.** Per run the "
        "count is off by up to a few fish of ~16 (fragments of a fish whose echo merged with a "
        "neighbour's, or a fish seen only in the record's last pings, which cannot be confirmed). "
        "Densities: *track* = fish-seconds the tracks spend in the volume / duration / volume; "
        "*true* = mean true number in the volume / volume; *per ping* = the per-ping count after "
        "interferometry / volume, which at these levels counts the strong fish's sidelobes, ghosts "
        "and far range sidelobes as well (docs/validation.md, migrating school) — the tracker's "
        "single-target rules and confirmation remove them.\n\n"
        + table(["seed", "true passages", "tracks counted", "error", "IDF1", "MOTA", "MOTP (cm)",
                 "ID switches", "fragmentations", "speed error (m/s)", "TS error (dB)",
                 "track density (m⁻³)", "true density (m⁻³)", "per-ping density (m⁻³)"], per_seed)
        + f"\n\nTracking time {t_default:.2f} s per run of {sc.pings.count} pings (the detections "
        "given). Speed error = track speed − the fish's mean speed over the track's pings; TS error "
        "= track TS (10 log10 of the mean σ_bs of its compensated detections) − the fish's, both "
        "as mean ± standard deviation over the tracks that follow a fish.\n\n"
        "![tracks of the first run](figures/school_tracks_tracks.png)\n\n"
        "![TS of the counted tracks: per-track mean and spread, histogram](figures/school_tracks_track_ts.png)\n\n"
        "**Decision rules, swept one at a time** (totals over the same runs; the rules are not "
        "approximations of a reference, so they live here rather than in docs/accuracy.md):\n\n"
        + table(["setting", "tracks counted", "true passages", "count error (%)", "mean IDF1",
                 "worst IDF1", "ID switches", "speed error sd (m/s)", "time per run (s)"], sweep_rows)
        + "\n\nWhat the sweeps say: `min_ts_db` (the single-target TS threshold) removes the far "
        "range sidelobes of the Hamming range window (≈ −80 dB, 2–3 m either side of a strong "
        "echo), which at 85 dB SNR lie above the noise and form slow false tracks under the fish; "
        "once it is in place `sidelobe_db` (a fish's own azimuth sidelobes and grating ghosts) "
        "matters little here — off, the count is 2 % higher and IDF1 slightly better, at twice "
        "the tracking time; it is kept on for scenes of stronger targets, where ghosts above the "
        "TS threshold enter the volume; "
        "`interference_db` caps a strong echo's effective SNR in its position covariance — "
        "without the cap (40 dB) the tracker trusts millimetre covariances that merged echoes "
        "violate by centimetres, and tracks break; `accel_sd_m_s2` trades following turns "
        "against jumping to a neighbour (these fish swim nearly straight, so 0.03 scores best; the "
        "default 0.1 is kept for fish that turn).")
