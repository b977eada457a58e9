"""simrunner batch --ray: a small batch on a local Ray cluster bound to 127.0.0.1 (started and
stopped by the tests, bounded in time) gives the local pool's rows bit for bit, and a
crashing, dying or hanging run is recorded with its reason without stopping the batch."""
from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import pytest
from helpers import C_CTOR_ENDS, C_CTOR_FAULT, FAULTY, STUCK

from simrunner.workflows.batch import deterministic, run_batch
from simrunner.workflows.batch.ray_backend import LOOPBACK_ENV

# Ray reads its loopback switch when imported, in the cluster's processes and in this driver
os.environ.setdefault(*LOOPBACK_ENV)
ray = pytest.importorskip("ray")
LOOPBACK_HEX = {"0100007F", "0000000000000000FFFF00000100007F", "00000000000000000000000001000000"}

REPO = Path(__file__).resolve().parents[1]
FOLLOWER = REPO / "examples" / "line_follower.py"
START_TIMEOUT_S = 90.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listening(pids: set[int]) -> set[str]:
    """The local addresses (``/proc/net`` hex) of the TCP sockets ``pids`` listen on."""
    inodes = set()
    for pid in pids:
        try:
            links = [os.readlink(f"/proc/{pid}/fd/{fd}") for fd in os.listdir(f"/proc/{pid}/fd")]
        except OSError:
            continue
        inodes |= {link[8:-1] for link in links if link.startswith("socket:[")}
    out = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            f = line.split()
            if f[3] == "0A" and f[9] in inodes:   # state LISTEN
                out.add(f[1].rsplit(":", 1)[0])
    return out


def _tree(root: int) -> set[int]:
    """``root`` and its live descendants."""
    parent = {}
    for entry in os.listdir("/proc"):
        try:
            parent[int(entry)] = int(Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (ValueError, OSError):
            continue
    out, todo = set(), [root]
    while todo:
        pid = todo.pop()
        out.add(pid)
        todo += [c for c, p in parent.items() if p == pid and c not in out]
    return out


def _wait_port(port: int, proc: subprocess.Popen, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"ray start exited with {proc.returncode}")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.5)
    raise TimeoutError(f"the Ray head did not listen on 127.0.0.1:{port} within {timeout_s:g} s")


@pytest.fixture(scope="module")
def ray_cluster():
    """``ray start --head --block`` in its own session, bound to 127.0.0.1, 2 CPUs, small
    object store, shared by this module's tests; stopped by Ctrl-C, then signalling its process group
    (only the processes it started). Token authentication is off for this loopback-only
    cluster (cluster and driver alike, so a token left in ~/.ray by another Ray run does not
    get in the way)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RAY_AUTH_MODE", "disabled")
        mp.setenv("RAY_USAGE_STATS_ENABLED", "0")
        yield from _cluster()


def _default_sigint() -> None:
    """In the ``ray start`` child before it runs: Ctrl-C back to its default. A shell without job
    control starts a background job (``make test &``, nohup, some CI runners) with SIGINT
    ignored, which its children inherit; Python then installs no KeyboardInterrupt handler and
    the SIGINT below did nothing: each teardown waited its whole 15 s, then killed the group."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _cluster():
    port = _free_port()
    temp = tempfile.mkdtemp(prefix="rt", dir="/tmp")
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    ray_cli = Path(sys.executable).parent / "ray"
    proc = subprocess.Popen(
        [str(ray_cli), "start", "--head", "--block", "--node-ip-address=127.0.0.1",
         f"--port={port}", "--num-cpus=2", "--include-dashboard=false",
         "--object-store-memory=100000000", f"--temp-dir={temp}", "--disable-usage-stats"],
        env=env, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        preexec_fn=_default_sigint)
    try:
        _wait_port(port, proc, START_TIMEOUT_S)
        assert _listening(_tree(proc.pid)) <= LOOPBACK_HEX   # no server on other interfaces
        yield f"127.0.0.1:{port}"
    finally:
        # Ctrl-C to `ray start --block` shuts its cluster down in ~2 s (SIGTERM to the group
        # took over 30 s); then anything left of the group is killed
        try:
            os.kill(proc.pid, signal.SIGINT)
            proc.wait(timeout=15.0)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            pass
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # anything left of the group
        except ProcessLookupError:
            pass
        shutil.rmtree(temp, ignore_errors=True)  # the cluster's session files and logs


def test_ray_cluster_rows_equal_local_pool(ray_cluster, tmp_path):
    common = dict(tracks=["random:1", str(REPO / "examples" / "oval_start.txt")], seeds=1,
                  params=["v_max=2.0,2.8"], time_limit_s=3.0, plot=False)
    on_ray = run_batch(FOLLOWER, out_dir=tmp_path / "ray", ray=ray_cluster, **common)
    assert on_ray.backend.startswith("ray") and on_ray.workers == 2
    local = run_batch(FOLLOWER, out_dir=tmp_path / "local", workers=2, **common)
    assert len(on_ray.rows) == 4
    assert [deterministic(r) for r in on_ray.rows] == [deterministic(r) for r in local.rows]
    assert not ray.is_initialized()   # the driver left the cluster
    timing = on_ray.worker_timing     # the actors reported ready before their first row
    assert sum(w.runs for w in timing) == 4
    assert all(w.started_at <= w.ready_at <= w.first_row_at <= w.last_row_at for w in timing)


def test_ray_faulty_runs_never_stop_the_batch(ray_cluster, tmp_path):
    """One actor: ``slow`` is queued on it behind ``die`` (the actor dies with the call
    queued), then ``drive`` behind ``slow`` (the actor is killed at the timeout): both queued
    runs go to a new actor and run."""
    ctl = tmp_path / "faulty.py"
    ctl.write_text(textwrap.dedent(FAULTY))
    res = run_batch(ctl, out_dir=tmp_path / "out", params=["mode=die,slow,drive,crash"],
                    time_limit_s=1000.0, run_timeout_s=8.0, csv="failures", ray=ray_cluster,
                    workers=1, tracks=[str(REPO / "examples" / "oval_start.txt")])
    by_mode = {r["mode"]: r for r in res.rows}
    assert by_mode["drive"]["outcome"] == "off_track"
    assert by_mode["crash"]["outcome"] == "controller_error" and "boom" in by_mode["crash"]["message"]
    assert by_mode["die"]["outcome"] == "worker_died" and "Ray worker died" in by_mode["die"]["message"]
    assert by_mode["slow"]["outcome"] == "wall_timeout"
    assert len(res.worker_timing) == 3      # the first actor died, the second was killed
    runs = sorted(p.name for p in (tmp_path / "out" / "runs").iterdir())
    assert runs == ["run_00002.csv", "run_00003.csv"]  # failures re-run with a CSV: off track, crash
    assert not ray.is_initialized()




def test_ray_run_stuck_in_one_c_call_names_its_line_as_drive_does(ray_cluster, tmp_path):
    """The hard watchdog ends the actor; on a cluster sharing this file system the row is
    drive's (outcome stalled, the controller's file:line), as with the local pool."""
    from simrunner.run.postmortem import stuck_message

    ctl = tmp_path / "ctrl.py"
    ctl.write_text(textwrap.dedent(STUCK))
    res = run_batch(ctl, out_dir=tmp_path / "out", params=["mode=stuck,drive"], wall_limit_s=0.5,
                    workers=2, plot=False, ray=ray_cluster)
    stuck, fine = res.rows
    assert stuck["outcome"] == "stalled", stuck
    assert stuck["message"] == stuck_message("ctrl.py:7 in main", 0.5)
    assert fine["outcome"] == "controller_returned"
    assert not ray.is_initialized()


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_ray_fault_in_a_c_constructor_at_the_load_names_its_line_as_drive_does(ray_cluster, tmp_path,
                                                                               monkeypatch):
    """A fault in a C constructor as the actor loads the program kills the actor: the row was
    worker_died with Ray's message; now drive's, as with the local pool (controller_error, the
    constructor's file:line)."""
    monkeypatch.chdir(tmp_path)
    ctl = tmp_path / "boom.c"
    ctl.write_text(C_CTOR_FAULT)
    res = run_batch(ctl, out_dir=tmp_path / "out", seeds=1, workers=1, plot=False, ray=ray_cluster)
    row, = res.rows
    assert row["outcome"] == "controller_error", row
    assert row["message"].startswith("boom.c:5: SIGSEGV: segmentation fault (in boom())"), row["message"]
    assert not ray.is_initialized()


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_ray_exit_in_a_c_constructor_at_the_load_is_told_as_drive_tells_it(ray_cluster, tmp_path, monkeypatch):
    """exit(3) in a C constructor as the actor loads the program ends the actor's process (status
    70): the row was worker_died with Ray's message; now drive's, as with the local pool."""
    monkeypatch.chdir(tmp_path)
    body, outcome, said = C_CTOR_ENDS["exit3.c"]
    ctl = tmp_path / "exit3.c"
    ctl.write_text(body)
    res = run_batch(ctl, out_dir=tmp_path / "out", seeds=1, workers=1, plot=False, ray=ray_cluster)
    row, = res.rows
    assert (row["outcome"], row["message"]) == (outcome, f"{said}, in a constructor as the program loaded, before "
                                                         "the first frame"), row
    assert not ray.is_initialized()


def test_private_local_ray_listens_only_on_loopback(tmp_path):
    """``--ray`` without an address: every server of the private Ray (GCS, raylet, agents,
    workers, this driver's) listens on 127.0.0.1 only."""
    seen: list[set[str]] = []
    res = run_batch(FOLLOWER, out_dir=tmp_path / "r", ray="local", workers=1, time_limit_s=1.0,
                    plot=False, on_row=lambda row: seen.append(_listening(_tree(os.getpid()))))
    assert res.rows[0]["outcome"] and len(seen) == 1
    assert seen[0] and seen[0] <= LOOPBACK_HEX, seen
    assert not ray.is_initialized()


def test_ray_address_that_does_not_answer(tmp_path):
    from simrunner.workflows.batch import BatchError

    with pytest.raises(BatchError, match="cannot connect"):
        run_batch(FOLLOWER, out_dir=tmp_path / "x", ray=f"127.0.0.1:{_free_port()}", time_limit_s=1.0)
