"""Backscatter: calibration, echo integration, Sv/MVBS/NASC, single targets and their TS."""
