"""Detection (thesis chapter 5): noise fits, thresholds and CFAR, peaks, 3-D location, scoring
against the truth."""
