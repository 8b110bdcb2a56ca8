"""Reference target strengths of pressure-release prolate spheroids from an independent model:
the prolate spheroidal modal series (PSMS; Furusawa 1988) of ICES echoSMs.

echoSMs is not a dependency of abacus (it pulls in a modal-series stack abacus does not need at
run time); the tests read only the values this script writes. Run it in a separate environment:

    python -m venv /work/venvs/echosms && /work/venvs/echosms/bin/pip install echosms==0.24.0
    /work/venvs/echosms/bin/python benchmarks/fish_ts_reference.py

It writes tests/data/psms_reference.json, which tests/test_fish_ts.py compares abacus' physical
optics with. Tilt 0 exactly is left out: echoSMs' PSMS returns a value 2.3 dB above its own
neighbours 0.1° away (a numerical artefact of the series at θ = 90°; a 10 cm body's lobe is 1°
wide), so the table starts at 0.1°.
"""
import json
import sys
from importlib.metadata import version
from pathlib import Path

import echosms
from echosms import boundary_type as bt

C, RHO, F = 1500.0, 1026.0, 420e3
BLADDERS = [(0.030, 0.005), (0.050, 0.010), (0.060, 0.008), (0.015, 0.0025)]   # a, b (m): kb 8.8, 17.6, 14.1, 4.4
TILTS = [0.1, 0.5, 1.0, 2.0, 3.0, 5.0, 7.0, 10.0, 15.0, 20.0, 30.0, 45.0, 60.0, 90.0]

model = echosms.PSMSModel()
rows = []
for a, b in BLADDERS:
    for tilt in TILTS:
        ts = model.calculate_ts_single(medium_c=C, medium_rho=RHO, a=a, b=b, theta=90.0 - tilt, f=F,
                                       boundary_type=bt.pressure_release, validate_parameters=False)
        rows.append({"a_m": a, "b_m": b, "tilt_deg": tilt, "ts_db": round(float(ts), 4)})
        print(a, b, tilt, rows[-1]["ts_db"], flush=True)
out = Path(__file__).resolve().parent.parent / "tests" / "data" / "psms_reference.json"
out.write_text(json.dumps({"model": "echoSMs PSMSModel (Furusawa 1988), pressure-release",
                           "echosms_version": version("echosms"), "python": sys.version.split()[0],
                           "sound_speed_m_s": C, "frequency_hz": F, "rows": rows}, indent=1) + "\n")
print(f"wrote {out}")
