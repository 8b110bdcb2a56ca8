"""Make the sample recording that ships with abacus: ``scenes/samples/recording.mat``.

Three pings of ``scenes/pelagic_fish.yaml`` (a herring school at physical levels, 16-bit ADC),
simulated and written as a MATLAB v5 recording of per-element samples in the fields
``abacus convert`` reads (processing.base.convert.MAT_FIELDS): the samples as the ADC's integer
counts (int16 ``samples_r`` / ``samples_i``), kept from 12 to 27 m only (the imaged 13–26 m and
the range filter's margin) so that the file stays small (≈ 0.5 MB). Like a recording, it carries
no ground truth and no calibration: its figures are in dB re the image's maximum.

    python benchmarks/sample_recording.py
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import scipy.io

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "scenes" / "samples" / "recording.mat"
PINGS = 3
RANGE_M = (12.0, 27.0)


def main() -> Path:
    import acoustics
    import processing
    from processing.backscatter.calibration import absorption_at_carrier
    from processing.base.contract import ELEMENT_GROUP, SONAR_GROUP
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = acoustics.simulate(acoustics.load_scene("pelagic_fish"), pings=range(PINGS))
    rec = processing.read_record(tree)
    x = np.asarray(rec.samples[:], complex)               # (pings, elements, samples), counts
    t = rec.time_offset_s + np.arange(x.shape[-1]) / rec.rate_hz
    r = rec.sound_speed_m_s * t / 2
    keep = np.flatnonzero((r >= RANGE_M[0]) & (r <= RANGE_M[1]))
    x = x[..., keep[0]:keep[-1] + 1]
    assert np.array_equal(x.real, np.round(x.real)) and np.abs(x).max() < 2**15, "not 16-bit counts"
    sonar = tree[SONAR_GROUP].ds
    eg = tree[ELEMENT_GROUP].ds
    ping_s = tree[ELEMENT_GROUP]["ping_time"].values.astype("datetime64[ns]").astype(np.int64) / 1e9
    fields = {
        "samples_r": x.real.astype(np.int16), "samples_i": x.imag.astype(np.int16),
        "fs": rec.rate_hz, "f0": rec.center_frequency_hz, "bandwidth": rec.bandwidth_hz,
        "replica": np.asarray(rec.replica, complex), "c": rec.sound_speed_m_s,
        "element_xyz": rec.element_position_m,
        "element_subarray": np.array([str(s) for s in rec.element_subarray]),
        "element_size": np.stack([eg["element_width"].values, eg["element_height"].values], -1),
        "tx_xyz": rec.transmitter_position_m, "tx_weight": rec.transmitter_weight,
        "tx_size": np.stack([sonar["tx_element_width"].values, sonar["tx_element_height"].values], -1),
        "t0": float(t[keep[0]]), "mode": rec.mode,
        "alpha": absorption_at_carrier(tree),
        "tx_beamwidth_deg": [float(sonar["beamwidth_transmit_major"].values),
                             float(sonar["beamwidth_transmit_minor"].values)],
        "ping_time": ping_s - ping_s[0],
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    scipy.io.savemat(OUT, fields, do_compression=True)
    print(f"wrote {OUT.relative_to(ROOT)}: {OUT.stat().st_size / 1e6:.2f} MB, {x.shape[0]} pings x "
          f"{x.shape[1]} elements x {x.shape[2]} samples")
    return OUT


if __name__ == "__main__":
    main()
