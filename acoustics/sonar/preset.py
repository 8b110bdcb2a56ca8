"""The ABACUS sonar in numbers: every constant of the thesis' system, in one place.

Values from the thesis (§3.1–3.6, Tables 3.1–3.4) as collected in
``../shared/reference/ABACUS.md``; where the thesis leaves a dimension open or prints a value
that contradicts its own results, the choice and its reason are in docs/arrays.md. Scene-file
defaults, the array builders and the benchmarks read these names; nothing else types them.
"""
from __future__ import annotations

# ------------------------------------------------------------------ signal (Table 3.1)
#: Carrier (centre) frequency f0 (Hz).
CENTER_FREQUENCY_HZ = 420_375.0
#: LFM swept bandwidth B (Hz).
BANDWIDTH_HZ = 20_000.0
#: Pulse duration (s).
PULSE_DURATION_S = 0.007
#: Ping interval (s): ABACUS runs at 1 Hz.
PING_INTERVAL_S = 1.0

# ------------------------------------------------------------- sampling (Tables 3.4, §3.6)
#: Complex baseband sampling rate (Hz).
SAMPLE_RATE_HZ = 45_455.0
#: Samples per channel and ping.
SAMPLES_PER_PING = 4096
#: k: ADC counts per unit pressure (a unit-driven element gives pressure 1 at 1 m on axis).
ADC_SCALE_COUNTS = 16384.0
#: ADC resolution (bits per I and Q).
ADC_BITS = 12
#: Receiver noise σ (ADC counts) of each quadrature component, after band-limiting.
NOISE_SIGMA_COUNTS = 126.68
#: Recorded channels of the data capture system.
RECORDED_CHANNELS = 16

# ------------------------------------------------------------ arrays (§3.1, Tables 3.2–3.3)
#: Elements per transmitter and per receiver subarray.
ELEMENTS_PER_ARRAY = 16
#: Transmitter element size (m): 0.020 along x, 0.012 along y (thesis §3.1).
TX_ELEMENT_M = (0.020, 0.012)
#: Receiver element size (m): 0.012 along x, 0.020 along y.
RX_ELEMENT_M = (0.012, 0.020)
#: Receiver pitch d along x (m).
RX_PITCH_M = 0.015
#: Vertical separation of the phase centres of subarrays A and B (m).
BASELINE_M = 0.0241
#: Transmitter stagger (m). The thesis prints 0.015 m, but only ±1.5 mm reproduces its
#: Table 3.2 (10.28° x 0.86°); ±15 mm gives a 3.3° azimuth beam. See docs/arrays.md.
TX_STAGGER_M = 0.0015
#: Transmitter elements rotated 90° at each end.
TX_ROTATED_END_ELEMENTS = 3
#: Receiver vertical stagger (m), not given in the thesis; ±2.0 mm gives the 8.80°
#: elevation beamwidth of Table 3.3 (8.78°). The ghost angle arcsin(λ/2d) is independent of it.
RX_STAGGER_M = 0.0020
#: Subarray B's shift along x (m): half a pitch, so that A and B interleave (the thesis'
#: "combined" mode and its remark that the baseline is not exactly along y, §5.3.3).
SUBARRAY_B_OFFSET_M = 0.0075

# ------------------------------------------------------------------ water (§6.1)
#: Sound speed (m/s) of the thesis' simulations.
SOUND_SPEED_M_S = 1530.0
