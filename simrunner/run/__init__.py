"""One run: the lockstep clock, the Spinner API, the judge, the controllers, and
:func:`~simrunner.run.runner.drive` that wires them (with the run log of
:mod:`simrunner.telemetry` and the outputs of :mod:`simrunner.reports`)."""
