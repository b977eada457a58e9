"""The local process backend of the batch scheduler (:mod:`.scheduler`): worker processes
on this machine, one pipe each (the Ray backend is :mod:`.ray_backend`).

Local workers are processes of the ``forkserver`` start method (``spawn`` where there is
none): dartpy worlds cannot be pickled or forked safely, so every worker builds its own.
"""
from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import time
from dataclasses import dataclass
from typing import Any

from simrunner.workflows.batch.scheduler import Handle
from simrunner.workflows.batch.spec import BatchConfig, Job


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
        try:
            h.ref.conn.send((job, outputs))
        except (OSError, ValueError):
            pass  # the worker has died (its pipe is closed): wait() reports it

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
