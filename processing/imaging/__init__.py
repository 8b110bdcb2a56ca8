"""Imaging (thesis chapter 4): pulse compression, beamforming, the images and their
interferometric phase and elevation."""
