"""The gap workflow while it runs: what it has found so far (:class:`Findings`) and the time it
may take (:class:`Budget`).

``run_gap(..., findings=Findings(listener))`` records each finding as it is made - a log read
(its windows and glitches), the nominal car's held-out gap, each chain step (the effect kept or
why none), each exchange and removal, the stages with the number of fits they run - and hands
every one to ``listener(finding)``: ``simrunner gap`` prints its ``text`` above the progress
bar and appends it to ``DIR/findings.txt``. A run stopped before its end (Ctrl-C, SIGTERM, an
error) still has them: :func:`simrunner.workflows.gap.report.write_partial` writes the partial
report from the findings.

``run_gap(..., budget=Budget(seconds))`` stops the chain in time: before each fit the chain asks
:meth:`Budget.spent`, which keeps back the time the closing stages (the kept parameters'
uncertainty, the held-out check) will take with one more effect, measured on this run's own
replays (:meth:`Budget.measure`). The model is then the best so far (the steps finished), and
the report says the budget stopped it.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

from simrunner.workflows.gap import GapError


@dataclass(frozen=True)
class Finding:
    """One finding: ``kind`` (``log``, ``nominal``, ``stage``, ``step``, ``exchange``,
    ``removed``, ``chain``, ``done``), a one-line ``text`` for a person, the seconds since the
    run began, and its figures (``data``, JSON-able)."""

    kind: str
    text: str
    elapsed_s: float
    data: dict = field(default_factory=dict)

    def line(self) -> str:
        """``[m:ss] text``: the line ``findings.txt`` and the terminal show."""
        m, s = divmod(int(self.elapsed_s), 60)
        return f"[{m}:{s:02d}] {self.text}"


class Findings:
    """The findings of one run, in the order made; ``listener`` (optional) is called with each.

    Besides the list, it keeps what a partial report needs: the car the chain starts from
    (``base_car``), the kept parameters after the last finished step (``parameters``), the
    stage running now (``stage``) and the chain's stop reason once known."""

    def __init__(self, listener: Callable[[Finding], None] | None = None,
                 clock: Callable[[], float] = time.monotonic):
        self.listener = listener
        self.clock = clock
        self.started = clock()
        self.items: list[Finding] = []
        self.base_car = None
        self.parameters: dict[str, float] = {}
        self.effects: list[str] = []
        self.stage = "reading the logs"
        self.stop_reason = ""

    def elapsed_s(self) -> float:
        return self.clock() - self.started

    def add(self, kind: str, text: str, **data) -> Finding:
        f = Finding(kind, text, self.elapsed_s(), data)
        self.items.append(f)
        if kind == "stage":
            self.stage = data.get("stage", text)
        if self.listener is not None:
            self.listener(f)
        return f

    def model(self, effects: list[str], parameters: dict[str, float]) -> None:
        """The model as it stands after a finished step, exchange or removal."""
        self.effects, self.parameters = list(effects), dict(parameters)

    def of_kind(self, kind: str) -> list[Finding]:
        return [f for f in self.items if f.kind == kind]


class BudgetSpent(GapError):
    """Raised inside the chain when :meth:`Budget.spent`; the chain catches it and ends with
    the model of its finished steps."""


def uncertainty_replays(n_parameters: int) -> int:
    """The replays :func:`simrunner.workflows.gap.uncertainty.parameter_uncertainty` runs for
    ``n_parameters``: its stencil (the centre, +-step along each, the four corners of each
    pair) and +-step at half the physics step (those cost two replays each)."""
    k = n_parameters
    return (1 + 2 * k + 2 * k * (k - 1)) + 2 * (2 * k) if k else 0


class Budget:
    """A wall-time budget for one run (``seconds``; ``math.inf``: none).

    :meth:`measure` records what one screening replay and the closing stages cost on this
    run; :meth:`tick` that a fit (or a batch of fits) finished. :meth:`spent` is True when the
    time left is less than the closing stages would take with ``n_parameters``
    (``reserve_factor`` keeps a margin) plus the wait for the next fit to finish (the longest
    of the last three waits): the chain looks again only when a fit finishes."""

    def __init__(self, seconds: float, clock: Callable[[], float] = time.monotonic, *, reserve_factor: float = 1.5):
        if not seconds > 0:
            raise GapError(f"budget {seconds:g} s: expected a positive time")
        self.seconds = float(seconds)
        self.clock = clock
        self.started = clock()
        self.reserve_factor = reserve_factor
        self.replay_s = 0.0   # one replay of the screening windows with the current model
        self.closing_s = 0.0  # the held-out check and the report's replays
        self.jobs = 1
        self._last_tick = self.started
        self._waits: list[float] = []

    def measure(self, replay_s: float, closing_s: float, jobs: int) -> None:
        self.replay_s, self.closing_s, self.jobs = max(replay_s, 0.0), max(closing_s, 0.0), max(int(jobs), 1)
        self._last_tick = self.clock()  # the chain's first fit starts now

    def tick(self) -> None:
        now = self.clock()
        self._waits = (self._waits + [now - self._last_tick])[-3:]
        self._last_tick = now

    def wait_s(self) -> float:
        """The longest of the last three waits between fits (0 before the first)."""
        return max(self._waits, default=0.0)

    def left_s(self) -> float:
        return self.seconds - (self.clock() - self.started)

    def reserve_s(self, n_parameters: int) -> float:
        """The closing stages' time with ``n_parameters`` kept (margin included)."""
        unc = math.ceil(uncertainty_replays(n_parameters) / self.jobs) * self.replay_s
        return self.reserve_factor * (unc + self.closing_s)

    def spent(self, n_parameters: int) -> bool:
        return self.left_s() < self.reserve_s(n_parameters) + self.wait_s()

    def minutes(self) -> str:
        return f"{self.seconds / 60:.3g} min"
