"""Running a batch's jobs on workers: the scheduler (:func:`run_jobs`) and the local
process backend (:class:`LocalBackend`; the Ray one is :mod:`.ray_backend`).

A backend starts workers, hands one a job, waits for rows and stops a worker. The
scheduler keeps every worker busy, gives a worker the next job of the track it already has
loaded (a track is loaded by as few workers as possible), stops a run that passes the
per-run wall-clock timeout (its worker is killed and replaced) and records a worker that
dies during a run; neither stops the batch. A run's clock starts when it is
handed to a worker that has reported ready; until then (a new worker importing the
simulator) :data:`STARTUP_GRACE_S` applies.

Local workers are processes of the ``forkserver`` start method (``spawn`` where there is
none): dartpy worlds cannot be pickled or forked safely, so every worker builds its own.
"""
from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import time
from collections import OrderedDict, deque
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

from simrunner.workflows.batch.results import failure_row
from simrunner.workflows.batch.spec import BatchConfig, Job

STARTUP_GRACE_S = 120.0
"""Extra wall time for a worker's first run (process start, imports, first track)."""
_POLL_S = 0.5


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
    def start(self) -> Handle: ...
    def submit(self, h: Handle, job: Job, outputs: dict | None) -> None: ...
    def wait(self, busy: list[Handle], timeout_s: float) -> list[tuple[Handle, dict | None, str]]: ...
    def kill(self, h: Handle) -> None: ...
    def close(self) -> None: ...


# -- the local process backend ---------------------------------------------------------------
@dataclass(eq=False)
class _Proc:
    process: Any
    conn: Any


class LocalBackend:
    """Worker processes on this machine, one pipe each."""

    def __init__(self, config: BatchConfig, *, start_method: str | None = None, quiet: bool = True):
        methods = multiprocessing.get_all_start_methods()
        method = start_method or ("forkserver" if "forkserver" in methods else "spawn")
        self.ctx = multiprocessing.get_context(method)
        self.config, self.quiet = config, quiet
        self.handles: list[Handle] = []

    def start(self) -> Handle:
        from simrunner.workflows.batch.worker import worker_loop

        parent, child = self.ctx.Pipe()
        proc = self.ctx.Process(target=worker_loop, args=(child, self.config, self.quiet),
                                daemon=True, name="simrunner-batch-worker")
        proc.start()
        child.close()
        h = Handle(_Proc(proc, parent))
        self.handles.append(h)
        return h

    def submit(self, h: Handle, job: Job, outputs: dict | None) -> None:
        h.ref.conn.send((job, outputs))

    def wait(self, busy: list[Handle], timeout_s: float) -> list[tuple[Handle, dict | None, str]]:
        by_obj: dict[Any, Handle] = {}
        for h in busy:
            by_obj[h.ref.conn] = h
            by_obj[h.ref.process.sentinel] = h
        ready = multiprocessing.connection.wait(list(by_obj), timeout=max(timeout_s, 0.0))
        out, seen = [], set()
        for obj in ready:
            h = by_obj[obj]
            if id(h) in seen:
                continue
            seen.add(id(h))
            result = self._receive(h)
            if result is not None:
                out.append((h, *result))
        return out

    def _receive(self, h: Handle) -> tuple[dict | None, str] | None:
        conn, proc = h.ref.conn, h.ref.process
        try:
            while conn.poll():
                kind, value = conn.recv()
                if kind == "ready":
                    h.ready_at = time.monotonic()
                elif kind == "row":
                    return value, ""
                if kind == "fatal":
                    return None, f"worker could not start: {value}"
        except (EOFError, OSError):
            pass
        else:
            if proc.is_alive():
                return None  # only the 'ready' message so far
        proc.join(timeout=5.0)
        return None, f"worker process died during the run (exit code {proc.exitcode})"

    def kill(self, h: Handle) -> None:
        proc = h.ref.process
        if proc.is_alive():
            proc.kill()
        proc.join(timeout=10.0)
        h.ref.conn.close()
        if h in self.handles:
            self.handles.remove(h)

    def close(self) -> None:
        for h in list(self.handles):
            try:
                h.ref.conn.send(None)
            except (OSError, ValueError):
                pass
        deadline = time.monotonic() + 5.0
        for h in list(self.handles):
            h.ref.process.join(timeout=max(0.0, deadline - time.monotonic()))
            self.kill(h)


# -- the scheduler ------------------------------------------------------------------------------
@dataclass
class _Queue:
    """Pending jobs grouped by track, in job order."""

    groups: "OrderedDict[str, deque[Job]]" = field(default_factory=OrderedDict)
    taken: set = field(default_factory=set)   # track labels some worker has started

    def __len__(self) -> int:
        return sum(len(g) for g in self.groups.values())

    def add(self, job: Job) -> None:
        self.groups.setdefault(job.track.label, deque()).append(job)

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


def _deadline(h: Handle, submitted: float, run_timeout_s: float) -> float:
    """When a run handed to ``h`` at ``submitted`` is out of time."""
    if h.ready_at is None and h.runs == 0:
        return submitted + STARTUP_GRACE_S + run_timeout_s
    return max(submitted, h.ready_at or submitted) + run_timeout_s


def run_jobs(jobs: list[Job], backend: Backend, *, workers: int, run_timeout_s: float,
             laps: int, on_row: Callable[[dict], None],
             outputs: Callable[[Job], dict | None] = lambda job: None) -> list[WorkerTiming]:
    """Run every job; ``on_row`` gets each row as it comes (any order). Stops every worker
    at the end (also on Ctrl-C, which is re-raised). Returns every worker's timing (in
    start order, replaced workers included)."""
    queue = _Queue()
    for job in jobs:
        queue.add(job)
    started: list[Handle] = []

    def start() -> Handle:
        started.append(backend.start())
        return started[-1]

    idle = [start() for _ in range(min(workers, len(jobs)))]
    busy: dict[Handle, tuple[Job, float]] = {}
    try:
        while len(queue) or busy:
            while idle and len(queue):
                h = idle.pop()
                job = queue.pick(h)
                backend.submit(h, job, outputs(job))
                busy[h] = (job, time.monotonic())
            now = time.monotonic()
            deadlines = {h: _deadline(h, t0, run_timeout_s) for h, (_, t0) in busy.items()}
            wait_s = min([_POLL_S] + [d - now for d in deadlines.values()])
            for h, row, reason in backend.wait(list(busy), wait_s):
                job, _ = busy.pop(h)
                if row is None:
                    on_row(failure_row(job, laps, "worker_died", reason))
                    backend.kill(h)
                    if len(queue):
                        idle.append(start())
                    continue
                h.runs += 1
                h.last_row_at = time.monotonic()
                if h.first_row_at is None:
                    h.first_row_at = h.last_row_at
                on_row(row)
                idle.append(h)
            now = time.monotonic()
            for h, (job, t0) in list(busy.items()):
                if now > _deadline(h, t0, run_timeout_s):
                    busy.pop(h)
                    backend.kill(h)
                    on_row(failure_row(job, laps, "wall_timeout", (
                        f"the run passed the per-run wall-clock timeout of {run_timeout_s:g} s "
                        "(--run-timeout); its worker was stopped"), round(run_timeout_s, 4)))
                    if len(queue):
                        idle.append(start())
    finally:
        backend.close()
    return [WorkerTiming.of(h) for h in started]
