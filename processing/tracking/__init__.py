"""Tracking: filters (Kalman, alpha-beta), gating and assignment, the tracks of a record and
their scores against the truth."""
