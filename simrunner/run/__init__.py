"""One run: the lockstep clock, the Spinner API, the judge, the run log, video and plot,
and :func:`~simrunner.run.runner.drive` that wires them."""
