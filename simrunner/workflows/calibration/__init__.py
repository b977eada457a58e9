"""Calibration against the real car (thesis chapter 5): the measurements file
(:mod:`.measured`) and the simulated test cases (:mod:`.simtests`); the procedures are in
:mod:`simrunner.workflows.calibration.calibrate`."""
