"""Workflows over many simulated runs: excitation plans (``excite``), the thesis's
calibration procedures (``calibration``) and the sim-vs-real gap (``gap``)."""
