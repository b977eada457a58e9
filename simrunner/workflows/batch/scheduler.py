"""The batch scheduler: :func:`run_jobs` hands a batch's jobs to workers of a backend
(:class:`Backend`: the local processes of :mod:`.pool` or the Ray actors of
:mod:`.ray_backend`).

A backend starts workers, hands one a job, waits for rows and stops a worker. The
scheduler keeps every worker busy, gives a worker the next job of the track it already has
loaded (a track is loaded by as few workers as possible), hands it the job after that ahead
of time (:data:`PREFETCH`), stops a run that passes the per-run wall-clock timeout (its
worker is killed and replaced) and records a worker that dies during a run; neither stops
the batch, and jobs queued on such a worker go back to the queue. A run's clock starts when
it is the first of a worker's jobs and the worker has reported ready; until then (a new
worker importing the simulator) :data:`STARTUP_GRACE_S` applies.
"""
from __future__ import annotations

import os

import time
from collections import OrderedDict, deque
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

from simrunner.workflows.batch.results import failure_row
from simrunner.workflows.batch.spec import Job


def default_workers() -> int:
    """All cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


STARTUP_GRACE_S = 120.0
"""Extra wall time for a worker's first run (process start, imports, first track)."""
_POLL_S = 0.5
PREFETCH = 1
"""Jobs a worker is handed beyond the one it runs (see :func:`run_jobs`)."""


@dataclass(eq=False)
class Handle:
    """One worker as the scheduler sees it (backends keep their own fields in ``ref``).
    Times are ``time.monotonic()`` seconds."""

    ref: Any
    track: str | None = None      # label of the track of its last job (it has it loaded)
    runs: int = 0
    ready_at: float | None = None  # when the worker reported ready (None: not yet / unknown)
    started_at: float = field(default_factory=time.monotonic)
    first_row_at: float | None = None
    last_row_at: float | None = None
    jobs: deque = field(default_factory=deque)  # handed to it, in order; the first one runs
    since: float | None = None   # when the first of ``jobs`` was handed over or could start
    time_limits: dict = field(default_factory=dict)  # run -> its simulated-time limit (s), as reported


@dataclass(frozen=True)
class WorkerTiming:
    """When one worker started, reported ready and delivered its first and last rows
    (``time.monotonic()`` seconds; None: never), and how many rows it delivered. What
    :func:`run_jobs` returns, for benchmarks: a worker's steady rate is
    ``(runs - 1) / (last_row_at - first_row_at)``, its start-up ``ready_at - started_at``."""

    started_at: float
    ready_at: float | None
    first_row_at: float | None
    last_row_at: float | None
    runs: int

    @classmethod
    def of(cls, h: Handle) -> "WorkerTiming":
        return cls(h.started_at, h.ready_at, h.first_row_at, h.last_row_at, h.runs)


class Backend(Protocol):
    """Workers that run the jobs handed to them one at a time, in the order handed."""

    def start(self) -> Handle:
        """Start a worker (it reports ready by setting ``Handle.ready_at`` in :meth:`wait`)."""

    def submit(self, h: Handle, job: Job, outputs: dict | None) -> None:
        """Hand ``job`` to ``h``, also while it runs or holds earlier jobs."""

    def wait(self, busy: list[Handle], timeout_s: float) -> list[tuple[Handle, dict | None, str]]:
        """Wait up to ``timeout_s`` for the first job of any of ``busy``: ``(h, row, "")``, or
        ``(h, row_or_None, reason)`` where the worker died during it (the row, if the backend
        can tell how, else None: outcome ``worker_died`` with ``reason``); at most one per
        worker."""

    def kill(self, h: Handle) -> None:
        """Stop ``h`` now (the jobs it holds are dropped)."""

    def close(self) -> None:
        """Stop every worker."""


@dataclass
class _Queue:
    """Pending jobs grouped by track, in job order."""

    groups: "OrderedDict[str, deque[Job]]" = field(default_factory=OrderedDict)
    taken: set = field(default_factory=set)   # track labels some worker has started

    def __len__(self) -> int:
        return sum(len(g) for g in self.groups.values())

    def add(self, job: Job) -> None:
        self.groups.setdefault(job.track.label, deque()).append(job)

    def put_back(self, job: Job) -> None:
        """A job handed to a worker that never started it: first in its track's line."""
        self.groups.setdefault(job.track.label, deque()).appendleft(job)

    def pick(self, h: Handle) -> Job:
        if h.track in self.groups and self.groups[h.track]:
            label = h.track
        else:
            fresh = [lab for lab, g in self.groups.items() if g and lab not in self.taken]
            label = fresh[0] if fresh else max((lab for lab, g in self.groups.items() if g),
                                               key=lambda lab: len(self.groups[lab]))
        job = self.groups[label].popleft()
        if not self.groups[label]:
            del self.groups[label]
        self.taken.add(label)
        h.track = label
        return job


RunTimeout = float | Callable[[float | None], float]
"""The wall-clock limit of a run: seconds, or a function of the run's simulated-time limit
(None until its worker has reported it)."""


def _timeout(h: Handle, run_timeout_s: RunTimeout) -> float:
    """The wall-clock limit of the run ``h`` is running."""
    if callable(run_timeout_s):
        return run_timeout_s(h.time_limits.get(h.jobs[0].index))
    return run_timeout_s


def _deadline(h: Handle, run_timeout_s: RunTimeout) -> float:
    """When the run ``h`` is running (the first of ``h.jobs``) is out of time."""
    if h.ready_at is None and h.runs == 0:
        return h.since + STARTUP_GRACE_S + _timeout(h, run_timeout_s)
    return max(h.since, h.ready_at or h.since) + _timeout(h, run_timeout_s)


def run_jobs(jobs: list[Job], backend: Backend, *, workers: int, run_timeout_s: RunTimeout,
             laps: int, on_row: Callable[[dict], None],
             outputs: Callable[[Job], dict | None] = lambda job: None,
             prefetch: int = PREFETCH,
             on_lost: Callable[[Job], None] = lambda job: None) -> list[WorkerTiming]:
    """Run every job; ``on_row`` gets each row as it comes (any order); ``on_lost`` each job
    whose worker died or was stopped during it (before its row). Stops every worker
    at the end (also on Ctrl-C, which is re-raised). Returns every worker's timing (in
    start order, replaced workers included).

    A worker is handed up to ``prefetch`` jobs beyond the one it runs (while at least as
    many jobs as workers are still unassigned, so that no worker idles at the end behind
    another's queue): it starts its next run as soon as it ends one, without waiting for
    this process. Only the running job has a clock; when a run passes its timeout or its
    worker dies, the jobs queued behind it go back to the queue, and a new worker runs them.
    """
    queue = _Queue()
    for job in jobs:
        queue.add(job)
    live: list[Handle] = []
    started: list[Handle] = []

    def start() -> None:
        started.append(backend.start())
        live.append(started[-1])

    def retire(h: Handle, job: Job, row: dict) -> None:
        """``job`` (the one ``h`` ran) failed with ``row``: stop ``h``, requeue the rest."""
        h.jobs.popleft()
        h.time_limits.clear()
        for queued in reversed(h.jobs):
            queue.put_back(queued)
        h.jobs.clear()
        backend.kill(h)
        live.remove(h)
        on_lost(job)
        on_row(row)
        if len(queue):
            start()

    for _ in range(min(workers, len(jobs))):
        start()
    try:
        while len(queue) or any(h.jobs for h in live):
            for h in live:
                while len(queue) and (not h.jobs or (len(h.jobs) <= prefetch and len(queue) > len(live))):
                    job = queue.pick(h)
                    backend.submit(h, job, outputs(job))
                    if not h.jobs:
                        h.since = time.monotonic()
                    h.jobs.append(job)
            busy = [h for h in live if h.jobs]
            now = time.monotonic()
            wait_s = min([_POLL_S] + [_deadline(h, run_timeout_s) - now for h in busy])
            for h, row, reason in backend.wait(busy, wait_s):
                job = h.jobs[0]
                if reason:  # the worker died during the run (the backend may tell how: a row)
                    retire(h, job, row if row is not None else failure_row(job, laps, "worker_died", reason))
                    continue
                if row["run"] != job.index:
                    raise RuntimeError(f"worker answered run {row['run']} for run {job.index}")
                h.jobs.popleft()
                h.time_limits.pop(job.index, None)
                h.runs += 1
                h.last_row_at = time.monotonic()
                if h.first_row_at is None:
                    h.first_row_at = h.last_row_at
                h.since = h.last_row_at if h.jobs else None
                on_row(row)
            now = time.monotonic()
            for h in [h for h in busy if h in live and h.jobs]:
                if now > _deadline(h, run_timeout_s):
                    limit = _timeout(h, run_timeout_s)
                    retire(h, h.jobs[0], failure_row(h.jobs[0], laps, "wall_timeout", (
                        f"the run passed the per-run wall-clock timeout of {limit:g} s "
                        "(--run-timeout); its worker was stopped"), round(limit, 4)))
    finally:
        backend.close()
    return [WorkerTiming.of(h) for h in started]
