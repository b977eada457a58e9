"""Sim-to-real gap workflow (issue 4 sections 4-6): find where the simulator and a measured
log disagree, name the missing effect from ``simrunner.car.effects.EFFECTS``, fit it, and show
the gap shrink on held-out data.

Data flow::

    run log CSV --simrunner.run.log.read_log--> RunLog --logs.check_measured, logs.derive--> smoothed states
      --replay.replay_windows (per candidate car)--> predictions --replay.residuals-->
      --regimes / stats--> where it disagrees
      --fit.fit_all (one process per effect)--> ranking --fit.choose--> winner or "none"
      --report.run_gap--> DIR/{report.json, car.toml, gap_before_after.png, residuals_by_regime.png}

``synth.make_measured_log`` makes "measured" logs with a hidden effect for tests and the
bench. See docs/gap.md.
"""
from __future__ import annotations

from simrunner.errors import SimError
from simrunner.run.log import LogError  # a malformed log: ``path:line: what was expected``


class GapError(SimError):
    """Root of the gap workflow's errors (bad input, impossible request)."""


__all__ = ["GapError", "LogError"]
