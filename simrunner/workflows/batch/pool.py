"""The local process backend of the batch scheduler (:mod:`.scheduler`): worker processes
on this machine, one pipe each (the Ray backend is :mod:`.ray_backend`).

Warm workers: this process imports the simulator once (:func:`.worker.warm_up`) and forks
its workers from itself (start method ``fork``), so a worker is ready to run at once instead
of starting an interpreter and importing the simulator (~0.4 s each, which dominated short
batches). A fork is safe here because this process has built no dartpy world for the batch
(worlds are built in the workers, one per run) and runs no other thread: where it does (a
caller's threads, a Ray driver), or where there is no ``fork``, workers come from the
``forkserver`` (which imports the simulator once, for every later batch of this process) or
``spawn``. A worker runs many runs, each isolated as ``drive`` isolates it (the controller
file executed afresh, its working directory and environment restored after it).

When a worker dies during a run, the row says why, as ``simrunner drive`` does: a controller
stuck in one C-level call (the hard watchdog's stack dump, written to the worker's report
file, names the controller's file:line; outcome ``stalled``), or the signal that killed it.
"""
from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import shutil
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from simrunner.run.supervise import private_temp_dir
from simrunner.workflows.batch.scheduler import Handle
from simrunner.workflows.batch.spec import BatchConfig, Job
from simrunner.workflows.batch.worker import WARM_MODULES, death_row, warm_up, worker_loop


def fork_is_safe() -> bool:
    """This process can fork its workers: ``fork`` exists, only this thread runs Python code
    and no Ray driver is connected (its threads would be copied mid-work)."""
    if "fork" not in multiprocessing.get_all_start_methods() or threading.active_count() != 1:
        return False
    return not ("ray" in sys.modules and sys.modules["ray"].is_initialized())


def choose_start_method(wanted: str | None = None) -> str:
    """``wanted``, else ``fork`` where :func:`fork_is_safe`, else ``forkserver``, else ``spawn``."""
    if wanted:
        return wanted
    if fork_is_safe():
        return "fork"
    return "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"


@dataclass(eq=False)
class _Proc:
    process: Any
    conn: Any
    report: Path                                  # the hard watchdog's stack dump goes here
    jobs: deque = field(default_factory=deque)    # (job, outputs) handed over, in order


class LocalBackend:
    """Worker processes on this machine, one pipe each; warm (forked from this process)
    where that is safe (module docstring)."""

    def __init__(self, config: BatchConfig, *, start_method: str | None = None, quiet: bool = True):
        method = choose_start_method(start_method)
        self.ctx = multiprocessing.get_context(method)
        if method == "fork":
            warm_up()        # once, here: every worker forked later has it
        elif method == "forkserver":
            self.ctx.set_forkserver_preload(list(WARM_MODULES))  # (if it is not running yet)
        self.method = method
        self.config, self.quiet = config, quiet
        self.handles: list[Handle] = []
        self._dir = private_temp_dir("batch")  # (a killed batch's own removed at the next one)
        self._count = 0

    def start(self) -> Handle:
        self._count += 1
        report = self._dir / f"worker{self._count}.report"
        parent, child = self.ctx.Pipe()
        me = os.getpid() if self.method in ("fork", "spawn") else None  # (a forkserver's child: the server's)
        proc = self.ctx.Process(target=worker_loop, args=(child, self.config, self.quiet, str(report), me),
                                daemon=True, name="simrunner-batch-worker")
        proc.start()
        child.close()
        h = Handle(_Proc(proc, parent, report))
        self.handles.append(h)
        return h

    def submit(self, h: Handle, job: Job, outputs: dict | None) -> None:
        h.ref.jobs.append((job, outputs))
        try:
            h.ref.conn.send((job, outputs))
        except (OSError, ValueError):
            pass  # the worker has died (its pipe is closed): wait() reports it

    def wait(self, busy: list[Handle], timeout_s: float) -> list[tuple[Handle, dict | None, str]]:
        """As :meth:`.scheduler.Backend.wait`; a worker's death comes with the row of the
        run it died in (:func:`.worker.death_row`)."""
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
                elif kind == "start":   # (run index, its simulated-time limit)
                    h.time_limits[value[0]] = value[1]
                elif kind == "row":
                    h.ref.jobs.popleft()
                    return value, ""
                if kind == "fatal":
                    return None, f"worker could not start: {value}"
        except (EOFError, OSError):
            pass
        else:
            if proc.is_alive():
                return None  # only the 'ready' message so far
        proc.join(timeout=5.0)
        reason = f"worker process died during the run (exit code {proc.exitcode})"
        if not h.ref.jobs:
            return None, reason
        job, outputs = h.ref.jobs[0]
        return death_row(job, self.config, proc.exitcode, h.ref.report, outputs), reason

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
        shutil.rmtree(self._dir, ignore_errors=True)
