"""Calibration of the mirror posture from one image (paper section 3)."""
