"""Projector walls: rigs, their warps and blends, and the files calibration tools write."""
