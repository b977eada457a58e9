"""Sim-to-real gap workflow (issue 4 sections 4-6): find where the simulator and a measured
log disagree, name the missing effect from ``simrunner.car.effects.EFFECTS``, fit it, and show
the gap shrink on held-out data.

Data flow::

    telemetry CSV --logs.read_log--> MeasuredLog --logs.derive--> smoothed states
      --replay.replay_windows (per candidate car)--> predictions --replay.residuals-->
      --regimes / stats--> where it disagrees
      --fit.fit_all (one process per effect)--> ranking --fit.choose--> winner or "none"
      --report.run_gap--> DIR/{report.json, car.toml, gap_before_after.png, residuals_by_regime.png}

``synth.make_measured_log`` makes "measured" logs with a hidden effect for tests and the
bench. See docs/gap.md.
"""
from __future__ import annotations

try:  # the simulator package's exception root (docs/DESIGN.md), when present
    from simrunner.errors import SimError as _Root
except ImportError:  # pragma: no cover - until simrunner defines it
    _Root = ValueError


class GapError(_Root):
    """Root of the gap workflow's errors (bad input, impossible request)."""


class LogError(GapError):
    """A measured log is malformed. ``str(err)`` is ``path:line: what was expected``."""

    def __init__(self, path: str, line: int, message: str):
        self.path, self.line, self.message = str(path), int(line), message
        super().__init__(f"{self.path}:{self.line}: {message}")


__all__ = ["GapError", "LogError"]
