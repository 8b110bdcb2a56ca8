"""Figures of the application: images, detections, counts, tracks and beam patterns (matplotlib,
imported lazily)."""
