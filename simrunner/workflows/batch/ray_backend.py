"""The Ray backend of ``simrunner batch --ray [ADDRESS]``: one actor per worker, each holding
a :class:`~simrunner.workflows.batch.worker.WorkerState` (its car and loaded tracks), so the
rows are those of the local pool, bit for bit (the same :func:`execute_job`).

``address``: ``"local"`` starts a private local Ray instance bound to 127.0.0.1 (stopped at
the end; see :data:`LOOPBACK_ENV`); anything else is handed to ``ray.init(address=...)`` (``host:6379`` of a cluster
started with ``ray start --head``, or ``ray://host:10001``). Every node needs nxpcup-sim
installed (``pip install 'nxpcup-sim[ray]'``); ``--video``/``--csv`` files are written on the
node that ran the run (use a shared folder for DIR on a multi-node cluster).
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from simrunner.workflows.batch.scheduler import Handle, default_workers
from simrunner.workflows.batch.spec import BatchConfig, BatchError, Job

INSTALL_HINT = "pip install 'nxpcup-sim[ray]'"
LOCAL_OBJECT_STORE_BYTES = 128 * 1024 * 1024
LOOPBACK_ENV = ("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
"""Ray (2.60, Linux) turns a node address of 127.0.0.1 into the machine's routable address
and its servers then listen on every interface; with its cluster mode off (this variable,
meant for Windows and macOS) a node stays on 127.0.0.1. Ray reads it when it is imported, in
every process (driver, daemons, workers): a private local Ray sets it before importing Ray,
for this process and its children (so this process cannot join a multi-node cluster later)."""


def import_ray(*, loopback: bool = False):
    """``import ray`` (one line naming the install command if it is missing); ``loopback``:
    for a private local Ray, which must be bound to 127.0.0.1 (:data:`LOOPBACK_ENV`)."""
    name, value = LOOPBACK_ENV
    if loopback and os.environ.get(name) != value:
        if "ray" in sys.modules:
            raise BatchError(f"--ray without an address starts a private Ray bound to 127.0.0.1, "
                             f"which needs {name}={value} before Ray is imported (Ray was imported "
                             "already): set it, or give a cluster address")
        os.environ[name] = value
    try:
        import ray
    except ImportError:
        raise BatchError(f"--ray needs Ray, which is not installed: {INSTALL_HINT}") from None
    return ray


def _check_reachable(address: str, timeout_s: float = 5.0) -> None:
    """A ``host:port`` that accepts no TCP connection is one clear line at once (Ray itself
    retries for minutes)."""
    import socket

    hostport = address.removeprefix("ray://")
    host, sep, port = hostport.rpartition(":")
    if not sep or not port.isdigit():
        if address == "auto":
            return
        raise BatchError(f"--ray {address}: expected HOST:PORT, ray://HOST:PORT or no address")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as exc:
        raise BatchError(f"--ray {address}: cannot connect to the Ray cluster "
                         f"({exc.strerror or exc}); start one with 'ray start --head'") from None


class _RayWorker:
    """The actor: the state of one worker, and one run per call. Like a local worker it
    discards controllers' prints (``quiet``), imports everything a run needs before it
    answers :meth:`ready`, and runs under the hard watchdog, which writes its stack dump to
    ``report`` when a run is stuck in one C-level call (the driver reads it when it shares the
    actor's file system: a local Ray; elsewhere the row keeps Ray's message)."""

    def __init__(self, config: BatchConfig, quiet: bool = True, report: str | None = None):
        from simrunner.workflows.batch.worker import WorkerState, quiet_output, warm_up

        if quiet:
            quiet_output()
        warm_up()
        self.state = WorkerState(config)
        try:
            self.dump = open(report if report else os.devnull, "w", errors="replace")  # noqa: SIM115
        except OSError:  # another node: no such folder there
            self.dump = open(os.devnull, "w")  # noqa: SIM115

    def ready(self) -> None:
        return None

    def begin(self, job: Job) -> float | None:
        """Called just before :meth:`run` of ``job`` (an actor's calls run in order): its
        simulated-time limit, for its wall-clock timeout."""
        from simrunner.workflows.batch.worker import run_time_limit_s

        return run_time_limit_s(job, self.state)

    def run(self, job: Job, outputs: dict | None) -> dict:
        from simrunner.run.supervise import Supervision, supervised_by
        from simrunner.workflows.batch.worker import execute_job

        with supervised_by(Supervision(self.dump, csv_path=None)):
            return execute_job(job, self.state, outputs)


@dataclass(eq=False)
class _Actor:
    actor: Any
    ready: Any = None   # the ``ready()`` call's ref until it has answered
    futures: deque = field(default_factory=deque)  # of the runs handed to it, in order
    begins: deque = field(default_factory=deque)   # (run, ref of its begin() call), in order
    jobs: deque = field(default_factory=deque)     # (job, outputs) of ``futures``, in order
    report: str = ""                               # the hard watchdog's stack dump goes here


class RayBackend:
    """Starts (``"local"``) or joins a Ray cluster; :meth:`shutdown` leaves it."""

    def __init__(self, config: BatchConfig, *, address: str = "local", workers: int | None = None,
                 quiet: bool = True):
        local = address in (None, "", "local")
        joined = "ray" in sys.modules and sys.modules["ray"].is_initialized()  # the caller's Ray
        ray = import_ray(loopback=local and not joined)
        self.ray, self.config, self.quiet = ray, config, quiet
        if ray.is_initialized():
            self.owner = False
        elif local:
            ray.init(num_cpus=workers or default_workers(), include_dashboard=False,
                     object_store_memory=LOCAL_OBJECT_STORE_BYTES, log_to_driver=False,
                     _node_ip_address="127.0.0.1", configure_logging=False)
            self.owner = True
            if any(node.get("NodeManagerAddress") != "127.0.0.1" for node in ray.nodes()):
                ray.shutdown()
                raise BatchError(f"--ray: the private Ray did not stay on 127.0.0.1 (this Ray "
                                 f"version ignores {LOOPBACK_ENV[0]}): give a cluster address")
        else:
            _check_reachable(address)
            try:
                ray.init(address=address, log_to_driver=False, configure_logging=False)
            except (ConnectionError, RuntimeError, ValueError) as exc:
                raise BatchError(f"--ray {address}: cannot connect to the Ray cluster "
                                 f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
            self.owner = True
        cpus = int(ray.cluster_resources().get("CPU", 1))
        self.workers = int(workers) if workers else max(1, cpus)
        self._cls = ray.remote(num_cpus=1, max_restarts=0)(_RayWorker)
        self.handles: list[Handle] = []
        self._dir = tempfile.mkdtemp(prefix="simrunner-batch-ray-")
        self._count = 0

    def start(self) -> Handle:
        self._count += 1
        report = os.path.join(self._dir, f"actor{self._count}.report")
        actor = self._cls.remote(self.config, self.quiet, report)
        h = Handle(_Actor(actor, actor.ready.remote(), report=report))
        self.handles.append(h)
        return h

    def submit(self, h: Handle, job: Job, outputs: dict | None) -> None:
        """Queue a run on the actor (an actor runs its calls one at a time, in order)."""
        h.ref.begins.append((job.index, h.ref.actor.begin.remote(job)))
        h.ref.futures.append(h.ref.actor.run.remote(job, outputs))
        h.ref.jobs.append((job, outputs))

    def wait(self, busy: list[Handle], timeout_s: float) -> list[tuple[Handle, dict | None, str]]:
        ray = self.ray
        by_ref = {h.ref.futures[0]: h for h in busy}   # the run each actor is running
        starting = {h.ref.ready: h for h in busy if h.ref.ready is not None}
        begun = {h.ref.begins[0][1]: h for h in busy if h.ref.begins}
        ready, rest = ray.wait([*starting, *begun, *by_ref], num_returns=1, timeout=max(timeout_s, 0.0))
        if ready and rest:
            more, _ = ray.wait(rest, num_returns=len(rest), timeout=0)
            ready += more
        out = []
        for ref in ready:
            if ref in starting:   # the actor has imported everything: its run's clock starts
                h = starting[ref]
                h.ref.ready, h.ready_at = None, time.monotonic()
                continue
            if ref in begun:      # a run starts: its time limit (for its timeout)
                h = begun[ref]
                index, _ = h.ref.begins.popleft()
                try:
                    h.time_limits[index] = ray.get(ref)
                except ray.exceptions.RayError:
                    pass   # the actor died: its run's future says so
                continue
            h = by_ref[ref]
            h.ref.futures.popleft()
            job, outputs = h.ref.jobs.popleft()
            try:
                out.append((h, ray.get(ref), ""))
            except ray.exceptions.RayError as exc:
                first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
                out.append((h, self._stuck_row(h, job, outputs),
                            f"Ray worker died during the run ({type(exc).__name__}: {first})"))
        return out

    def _stuck_row(self, h: Handle, job: Job, outputs: dict | None) -> dict | None:
        """``simrunner drive``'s row for a run whose actor the hard watchdog ended (its stack
        dump readable here) or a fault in a C/C++ program's constructors or in a thread of its own
        killed (the host's report, :func:`~simrunner.run.postmortem.dead_fault`) or its exit, spinner_fail or misused
        call there ended (:func:`~simrunner.run.postmortem.load_end`), else None (the row keeps
        Ray's message)."""
        from simrunner.run.native.symbolize import load_end_report, load_fault_report, thread_fault_report
        from simrunner.workflows.batch.worker import death_row

        try:
            with open(h.ref.report, errors="replace") as fh:
                dump = fh.read()
        except OSError:
            return None
        told = "Timeout (" in dump or any(find(dump) is not None for find in (load_fault_report, thread_fault_report,
                                                                              load_end_report))
        return death_row(job, self.config, None, h.ref.report, outputs) if told else None

    def kill(self, h: Handle) -> None:
        try:
            self.ray.kill(h.ref.actor)
        except Exception:  # noqa: BLE001 - already gone
            pass
        if h in self.handles:
            self.handles.remove(h)

    def close(self) -> None:
        for h in list(self.handles):
            self.kill(h)

    def shutdown(self) -> None:
        self.close()
        shutil.rmtree(self._dir, ignore_errors=True)
        if self.owner and self.ray.is_initialized():
            self.ray.shutdown()
