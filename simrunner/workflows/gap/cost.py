"""What a gap run on a log will cost, said before the work: rows, seconds of data, memory,
time (issue 50: a 200 MB log kept ``simrunner gap`` at 0 fits for 10 minutes at 2.3 GB).

Most of a long log's time goes into replaying every second of it: the nominal car on the fit
windows at the fits' step and on all windows at the drive's step, the held-out windows at
each step of the chain, the final car on all windows. The screening and refits use at most
``settings.screen_max_s`` of windows, so they cost about the same on any log. The figures
are ``GapSettings`` fields measured on the development machine (2 CPUs, Python 3.11; their
derivations say how; ``docs/gap.md``, ``--max-rows``): estimates to decide by, not promises.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from simrunner.telemetry.log import FORMAT1_NAMES
from simrunner.workflows.gap.settings import SETTINGS, GapSettings


@dataclass(frozen=True)
class Cost:
    """``rows`` of data, ``data_s`` seconds of it (nan before reading), ``memory_mb`` and the wall
    time estimated: ``first_minutes`` to the chain's first step, ``minutes`` up to the end of a
    chain that takes its ``steps`` steps (``max_effects`` effects and the step that finds no
    more; a chain that stops sooner ends sooner)."""

    rows: int
    data_s: float
    memory_mb: float
    minutes: float
    first_minutes: float = math.nan
    steps: int = 1

    def text(self) -> str:
        data = f", {self.data_s:,.0f} s of data" if math.isfinite(self.data_s) else ""
        when = ""
        if math.isfinite(self.minutes):
            when = f", ~{self.minutes:.0f} min"
            if self.steps > 1 and math.isfinite(self.first_minutes):
                when = (f", ~{self.first_minutes:.0f} min to the first step, up to ~{self.minutes:.0f} min "
                        f"for a chain of {self.steps} steps")
        return f"{self.rows:,} rows{data}: ~{self.memory_mb / 1000:.1f} GB{when}"


def count_rows(path: str | Path) -> int:
    """The rows a log holds (its lines less the comments, blank lines and the header at its
    top), counted without parsing it (~1 s per GB)."""
    lines, head, last = 0, b"", b"\n"
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            if len(head) < 65536:
                head += chunk[:65536]
            lines += chunk.count(b"\n")
            last = chunk[-1:]
    if last != b"\n":
        lines += 1  # the last line without its newline
    return max(lines - _top_lines(head), 0)


def _top_lines(head: bytes) -> int:
    """The comments and blank lines before the header, and the header, at the top of ``head``."""
    top = 0
    for line in head.split(b"\n"):
        top += 1
        if line.strip() and not line.startswith(b"#"):
            break
    return top


def head_lines(path: str | Path, rows: int) -> int:
    """How many lines ``head -n`` keeps for the top lines (comments, header) and ``rows`` rows."""
    with open(path, "rb") as f:
        return _top_lines(f.read(65536)) + rows


def span_s(path: str | Path) -> float:
    """Seconds from the first row to the last of a log whose header names ``t_s`` (or format 1's
    ``t``, as the log reader takes it; read from its head and its tail only), else nan."""
    try:
        with open(path, "rb") as f:
            head = f.read(65536).split(b"\n")
            f.seek(0, 2)
            f.seek(max(f.tell() - 65536, 0))
            tail = [x for x in f.read().split(b"\n") if x.strip()]
        rows = [x for x in head if x.strip() and not x.startswith(b"#")]
        header = [FORMAT1_NAMES.get(h.strip(), h.strip()) for h in rows[0].decode("utf-8-sig", "replace").split(",")]
        col = header.index("t_s")
        return float(tail[-1].split(b",")[col]) - float(rows[1].split(b",")[col])
    except (OSError, ValueError, IndexError):
        return math.nan


def replay_cpu_s(data_s: float, dt_s: float, settings: GapSettings = SETTINGS) -> float:
    """CPU seconds to replay ``data_s`` seconds of log at physics step ``dt_s``."""
    return data_s * (settings.replay_cpu_base_s + settings.replay_cpu_step_s / dt_s)


def estimate(rows: int, data_s: float = math.nan, *, jobs: int = 2, n_effects: int = 24,
             settings: GapSettings = SETTINGS, held_dt_s: float = 0.002) -> Cost:
    """The :class:`Cost` of a gap run on ``rows`` rows covering ``data_s`` seconds (nan: not
    known yet, no time given) with ``n_effects`` candidates, from ``settings`` (fit step,
    screening seconds, chain length, held-out share, the measured rates)."""
    memory_mb = settings.cost_base_mb + rows * settings.cost_bytes_per_row / 1e6
    if not math.isfinite(data_s):
        return Cost(rows, data_s, memory_mb, math.nan)
    held_share = 1.0 / settings.holdout_every
    fit_s = data_s * (1.0 - held_share)
    steps = min(settings.max_effects, n_effects) + 1    # (the last finds nothing more to keep)
    nominal = (replay_cpu_s(fit_s, settings.workflow_dt_s, settings)            # the nominal fit windows
               + replay_cpu_s(data_s, held_dt_s, settings))                     # nominal: all windows
    step_replays = replay_cpu_s(data_s * held_share, held_dt_s, settings)       # each step's held-out check
    screened = min(settings.screen_max_s or fit_s, fit_s)

    def fits(k: int) -> float:  # step k screens the candidates left and refits with the effects kept
        return (settings.screen_wall_per_s * screened * max(n_effects - k, 0) / 24 * 2 / max(jobs, 1)
                * (1.0 + settings.screen_step_growth * k))

    first = nominal + step_replays + fits(0)
    whole = (nominal + replay_cpu_s(data_s, held_dt_s, settings)                # the final car: all windows
             + sum(step_replays + fits(k) for k in range(steps)))
    return Cost(rows, data_s, memory_mb, whole / 60.0, first / 60.0, steps)
