"""The batch scheduler (``run_jobs``) on an in-memory backend: jobs handed to a worker ahead
of time (prefetch) are never lost - when the run before them hangs or its worker dies they
go back to the queue and run on a new worker - every job gives exactly one row, and a worker
keeps to its track."""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

import pytest

from simrunner.workflows.batch.scheduler import Handle, run_jobs
from simrunner.workflows.batch.results import failure_row
from simrunner.workflows.batch.spec import Job, TrackRef

TIMEOUT_S = 0.3   # a hanging run's timeout (the scheduler's own clock; nothing is timed here)


@dataclass(eq=False)
class _Worker:
    number: int
    inbox: deque = field(default_factory=deque)
    alive: bool = True


class FakeBackend:
    """Workers that run each job at once according to ``fate[job.index]``: ``"ok"`` (a row),
    ``"die"`` (the worker dies) or ``"hang"`` (never answers). Records every hand-over."""

    def __init__(self, fate: dict[int, str], limits: dict[int, float] | None = None):
        self.fate = fate
        self.limits = limits or {}   # job -> the simulated-time limit its worker reports
        self.handed: list[tuple[int, int]] = []   # (worker number, job index)
        self.workers: list[_Worker] = []

    def start(self) -> Handle:
        self.workers.append(_Worker(len(self.workers)))
        h = Handle(self.workers[-1])
        h.ready_at = time.monotonic()
        return h

    def submit(self, h: Handle, job: Job, outputs) -> None:
        assert h.ref.alive
        h.ref.inbox.append(job)
        self.handed.append((h.ref.number, job.index))

    def wait(self, busy: list[Handle], timeout_s: float):
        out = []
        for h in busy:
            job = h.ref.inbox[0]
            if job.index in self.limits:
                h.time_limits[job.index] = self.limits[job.index]
            fate = self.fate.get(job.index, "ok")
            if fate == "ok":
                h.ref.inbox.popleft()
                out.append((h, failure_row(job, 1, "finished", f"worker {h.ref.number}"), ""))
            elif fate == "die":
                out.append((h, None, "died"))
        if not out:
            time.sleep(min(max(timeout_s, 0.0), 0.05))
        return out

    def kill(self, h: Handle) -> None:
        h.ref.alive = False

    def close(self) -> None:
        pass


def _jobs(n: int, tracks: int = 1) -> list[Job]:
    refs = [TrackRef(f"t{i}", path=f"/t{i}") for i in range(tracks)]
    return [Job(i, refs[i * tracks // n], 0) for i in range(n)]


def _run(jobs, backend, workers, prefetch=1):
    rows: list[dict] = []
    timing = run_jobs(jobs, backend, workers=workers, run_timeout_s=TIMEOUT_S, laps=1,
                      on_row=rows.append, prefetch=prefetch)
    return {r["run"]: r for r in rows}, rows, timing


@pytest.mark.parametrize("workers", [1, 2, 3])
@pytest.mark.parametrize("prefetch", [0, 1, 2])
def test_every_job_one_row_whatever_hangs_or_dies(workers, prefetch):
    fate = {1: "die", 4: "hang", 5: "die", 9: "hang"}
    backend = FakeBackend(fate)
    by_run, rows, timing = _run(_jobs(12), backend, workers, prefetch)
    assert sorted(r["run"] for r in rows) == list(range(12))   # one row each, none twice
    for i, row in by_run.items():
        expected = {"die": "worker_died", "hang": "wall_timeout"}.get(fate.get(i), "finished")
        assert row["outcome"] == expected, (i, row)
    assert sum(w.runs for w in timing) == 8
    # a failed worker is replaced while jobs are left; the timing lists every worker started
    assert len(timing) == len(backend.workers) <= workers + 4
    assert sum(not w.alive for w in backend.workers) == 4


def test_jobs_queued_behind_a_hung_or_dead_run_run_on_a_new_worker():
    backend = FakeBackend({0: "die", 2: "hang"})
    by_run, _, _ = _run(_jobs(6), backend, workers=1, prefetch=1)
    handed = backend.handed
    # job 1 was queued on the worker that died in job 0, then run by the next worker
    assert (0, 0) in handed and (0, 1) in handed
    assert [w for w, j in handed if j == 1] == [0, 1] and by_run[1]["message"] == "worker 1"
    # job 3 was queued behind the hanging job 2, then run by the worker that replaced it
    hung_on = next(w for w, j in handed if j == 2)
    assert [w for w, j in handed if j == 3] == [hung_on, hung_on + 1]
    assert by_run[3]["message"] == f"worker {hung_on + 1}"
    assert by_run[2]["outcome"] == "wall_timeout" and by_run[0]["outcome"] == "worker_died"


def test_no_prefetch_at_the_end_and_workers_keep_their_track():
    backend = FakeBackend({})
    _run(_jobs(8, tracks=2), backend, workers=2, prefetch=1)
    by_worker: dict[int, list[int]] = {}
    for w, j in backend.handed:
        by_worker.setdefault(w, []).append(j)
    assert sorted(j for js in by_worker.values() for j in js) == list(range(8))  # once each
    assert sorted(by_worker.values()) == [[0, 1, 2, 3], [4, 5, 6, 7]]            # one track each


def test_a_runs_timeout_follows_the_time_limit_its_worker_reports():
    """The default --run-timeout is a function of each run's own time limit (drive's default
    depends on the track): the scheduler applies what the worker reported for the run."""
    backend = FakeBackend({1: "hang", 2: "hang"}, limits={2: 0.2})
    rows: list[dict] = []
    seen: list = []

    def timeout(limit):
        seen.append(limit)
        return TIMEOUT_S if limit is None else 2 * limit

    run_jobs(_jobs(3), backend, workers=1, run_timeout_s=timeout, laps=1, on_row=rows.append)
    by_run = {r["run"]: r for r in rows}
    assert by_run[1]["wall_time_s"] == TIMEOUT_S and by_run[2]["wall_time_s"] == 0.4
    assert "timeout of 0.4 s" in by_run[2]["message"] and None in seen and 0.2 in seen
