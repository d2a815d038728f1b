"""Calibration of the simulated Husky against real drive recordings (assets/husky_a200/drive_recordings)."""
