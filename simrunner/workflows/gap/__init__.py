"""Sim-to-real gap workflow: find where the simulator and measured logs of one car
disagree, build the chain of catalogue effects (``simrunner.car.effects.EFFECTS``) that closes
the gap, and show it shrink on held-out data.

Data flow::

    run log CSV(s) --simrunner.telemetry.log.read_log (+ column mapping)--> RunLog
      --logs.check_measured, glitches.find_glitches, logs.derive--> smoothed states, clean pieces
      --replay.make_windows, split_windows--> fit and held-out windows (per log)
      --replay.replay / residuals (signals the logs support)--> where it disagrees (regimes)
      --chain.build_chain (fit.fit_all screening, joint refits, held-out confirmation)--> kept effects
      --workflow.run_gap--> GapResult: leftovers vs noise, effects the logs cannot reveal
      --report.write_outputs--> DIR/{report.json, car.toml, residuals.txt, findings.txt, *.png}

While it runs, ``live.Findings`` hands each finding to a listener as it is made (``simrunner gap``:
the terminal and DIR/findings.txt; ``report.write_partial`` when the run is stopped) and
``live.Budget`` ends the chain in time.

Every threshold: ``settings.SETTINGS`` (units, derivations). Entry: ``workflow.run_gap``.

``synth.make_measured_log`` makes "measured" logs with hidden effects for tests and the
bench. See docs/gap.md.
"""
from __future__ import annotations

from simrunner.errors import SimError
from simrunner.telemetry.log import LogError  # a malformed log: ``path:line: what was expected``


class GapError(SimError):
    """Root of the gap workflow's errors (bad input, impossible request)."""


__all__ = ["GapError", "LogError"]
