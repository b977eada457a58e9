"""simrunner batch's local workers (issue 50): forked warm from the batch's process, runs
still isolated from each other, and a worker that dies in a run reported as drive reports it."""
from __future__ import annotations

import shutil
import textwrap
import threading

import numpy as np
import pytest

from helpers import C_CTOR_ENDS, C_CTOR_FAULT, C_THREAD_FAULT, C_THREAD_OVERFLOW, STUCK

from simrunner.workflows.batch import deterministic, run_batch
from simrunner.workflows.batch.pool import LocalBackend, choose_start_method
from simrunner.workflows.batch.spec import BatchConfig

LEAKY = """
import os

seen = []   # a module global: fresh in every run (the file is executed afresh)

def main(s):
    s.get_image()
    report = f"env={os.environ.get('NXPCUP_LEAK', '')!r} cwd_root={os.getcwd() == '/'} seen={len(seen)}"
    seen.append(1)
    os.environ["NXPCUP_LEAK"] = "leaked"
    os.chdir("/")
    raise RuntimeError(report)
"""


def test_workers_fork_warm_unless_another_thread_runs():
    assert threading.active_count() == 1 and choose_start_method() == "fork", threading.enumerate()
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:   # a thread of the caller's could hold a lock the forked worker needs
        assert choose_start_method() in ("forkserver", "spawn")
    finally:
        stop.set()
        other.join()
    assert choose_start_method("spawn") == "spawn"


def test_warm_workers_keep_runs_isolated_and_rows_identical(tmp_path):
    ctl = tmp_path / "leaky.py"
    ctl.write_text(LEAKY)
    backend = LocalBackend(BatchConfig(controller=str(ctl)))
    assert backend.method == "fork"
    backend.close()
    rows = {}
    for workers in (1, 2):
        res = run_batch(ctl, out_dir=tmp_path / f"w{workers}", seeds=4, workers=workers, plot=False)
        rows[workers] = [deterministic(r) for r in res.rows]
        # every run of a worker saw no environment, directory or module state of the runs before
        assert [r["message"].split(" at ")[0] for r in res.rows] == [
            "RuntimeError: env='' cwd_root=False seen=0"] * 4
    assert rows[1] == rows[2]


C_LEAKY = r"""
#include <stdlib.h>
#include "spinner.h"
int main(void) {
    spinner_sleep(0.02);
    if (getenv("NXPCUP_C_LEAK") || !getenv("NXPCUP_C_KEEP"))
        spinner_sleep(0.1);  /* what an earlier run left shows in this run's simulated time */
    setenv("NXPCUP_C_LEAK", "leaked", 1);
    unsetenv("NXPCUP_C_KEEP");
    return 0;
}
"""


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_a_c_controllers_environment_does_not_reach_the_next_run(tmp_path, monkeypatch):
    """setenv / unsetenv in a C controller (in the worker's process) change the C library's
    environment behind os.environ: the next run of the worker saw them (rows differed between
    1 and 2 workers)."""
    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("NXPCUP_C_KEEP", "kept")
    monkeypatch.delenv("NXPCUP_C_LEAK", raising=False)
    ctl = tmp_path / "leaky.c"
    ctl.write_text(C_LEAKY)
    for workers in (1, 2):
        res = run_batch(ctl, out_dir=tmp_path / f"w{workers}", seeds=4, workers=workers, plot=False)
        assert [(r["outcome"], r["sim_time_s"]) for r in res.rows] == [("controller_returned", 0.02)] * 4


C_PUTENV = r"""
#include <stdlib.h>
#include "spinner.h"
static char keep[] = "NXPCUP_C_KEEP=kept";   /* the value it had: nothing to restore */
static char ctor[] = "NXPCUP_C_CTOR=1";
__attribute__((constructor)) static void at_load(void) { putenv(ctor); }  /* before the run */
int main(void) {
    putenv(keep);
    spinner_sleep(0.02);
    return 0;
}
"""


def _environ_addresses() -> list[int]:
    import ctypes

    env = ctypes.POINTER(ctypes.c_void_p).in_dll(ctypes.CDLL(None), "environ")
    out, i = [], 0
    while env and env[i]:
        out.append(env[i])
        i += 1
    return out


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_no_environment_string_is_left_in_a_c_controllers_library(tmp_path, monkeypatch):
    """putenv(3) puts the controller's own string in environ; when the value was the one it had
    (or the controller's library put it there as it was loaded), it stayed there, and the
    library is unloaded after the run: the next getenv of the process read unmapped memory
    (SIGSEGV in the next run of a batch worker, or at drive's end)."""
    import os

    from simrunner.run.native.controller import load_native
    from simrunner.run.runner import drive

    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("NXPCUP_C_KEEP", "kept")
    ctl = tmp_path / "putenv.c"
    ctl.write_text(C_PUTENV)
    try:
        ctrl = load_native([ctl])
        res = drive(ctrl, track="floor", time_limit_s=1.0)
        assert res.outcome == "controller_returned"
        library = os.path.realpath(ctrl.program.library)
        spans = []
        with open("/proc/self/maps") as fh:
            for line in fh:
                fields = line.split()
                if len(fields) >= 6 and os.path.basename(fields[5]) == os.path.basename(library):
                    lo, hi = (int(x, 16) for x in fields[0].split("-"))
                    spans.append((lo, hi))
        assert spans  # (still loaded: its NativeController lives)
        inside = [a for a in _environ_addresses() if any(lo <= a < hi for lo, hi in spans)]
        assert inside == []
        assert os.getenv("NXPCUP_C_KEEP") == "kept"
    finally:
        os.unsetenv("NXPCUP_C_CTOR")  # (set before the run: the environment the run started from)


UMASKED = """
import os

def main(s):
    os.umask(0o077)  # before the first frame: the run log is created at it
    s.get_image()
"""


def test_a_controllers_umask_does_not_reach_the_outputs_or_the_next_run(tmp_path):
    """os.umask (or a C controller's umask) in a run: drive's outputs and the run logs of the
    later runs of a batch worker were written 0600, which teammates cannot read."""
    import os
    import stat

    from click.testing import CliRunner

    from simrunner.cli import main as cli

    ctl = tmp_path / "umasked.py"
    ctl.write_text(UMASKED)
    old = os.umask(0o022)
    try:
        run_batch(ctl, out_dir=tmp_path / "b", seeds=3, workers=1, csv="all", plot=False)
        r = CliRunner().invoke(cli, ["drive", str(ctl), "--csv", str(tmp_path / "d.csv"),
                                     "--summary", str(tmp_path / "d.json"), "--plot", str(tmp_path / "d.png")])
        assert r.exit_code == 0, r.output
        assert os.umask(0o022) == 0o022  # (and the caller's mask is its own again)
    finally:
        os.umask(old)
    files = sorted((tmp_path / "b" / "runs").glob("*.csv")) + [tmp_path / f"d.{x}" for x in ("csv", "json", "png")]
    assert len(files) == 6
    assert {f.name: oct(stat.S_IMODE(f.stat().st_mode)) for f in files} == {f.name: "0o644" for f in files}


def test_a_controllers_umask_does_not_reach_the_folders_made_for_the_run_log(tmp_path):
    """The run log's folders, made at the first frame (after the controller's os.umask), were
    0700 while the file in them was 0644: teammates could not reach it."""
    import os
    import stat

    from simrunner.run.runner import drive

    ctl = tmp_path / "umasked.py"
    ctl.write_text(UMASKED)
    old = os.umask(0o022)
    try:
        drive(ctl, track="floor", time_limit_s=0.2, csv=tmp_path / "a" / "b" / "d.csv")
    finally:
        os.umask(old)
    modes = {p.name: oct(stat.S_IMODE(p.stat().st_mode))
             for p in (tmp_path / "a", tmp_path / "a" / "b", tmp_path / "a" / "b" / "d.csv")}
    assert modes == {"a": "0o755", "b": "0o755", "d.csv": "0o644"}


def test_a_run_stuck_in_one_c_call_names_its_line_as_drive_does(tmp_path):
    """The hard watchdog ends the worker; the row is drive's: outcome stalled, the
    controller's file:line, and (with its CSV) the frames and simulated time it reached."""
    from simrunner.run.postmortem import stuck_message

    ctl = tmp_path / "ctrl.py"
    ctl.write_text(textwrap.dedent(STUCK))
    res = run_batch(ctl, out_dir=tmp_path / "out", params=["mode=stuck,drive"], wall_limit_s=0.5,
                    workers=2, csv="all", plot=False)
    stuck, fine = res.rows
    assert stuck["outcome"] == "stalled", stuck
    assert stuck["message"] == stuck_message("ctrl.py:7 in main", 0.5)
    assert stuck["frames"] == 5 and stuck["sim_time_s"] > 0.0
    assert fine["outcome"] == "controller_returned" and fine["frames"] >= 5


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_a_fault_in_a_c_constructor_at_the_load_names_its_line_as_drive_does(tmp_path, monkeypatch):
    """A fault in a C constructor, as the worker loads the program's library before the run, kills
    the worker: its row was worker_died 'killed by SIGSEGV before the first frame'; now drive's:
    controller_error naming the constructor's file:line and function."""
    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    ctl = tmp_path / "boom.c"
    ctl.write_text(C_CTOR_FAULT)
    res = run_batch(ctl, out_dir=tmp_path / "out", seeds=1, workers=1, plot=False)
    row, = res.rows
    assert row["outcome"] == "controller_error", row
    assert row["message"].startswith("boom.c:5: SIGSEGV: segmentation fault (in boom()), in a constructor as the "
                                     "program loaded"), row["message"]
    assert row["frames"] == 0


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_an_earlier_batchs_run_csv_is_not_read_as_a_dead_runs_log(tmp_path, monkeypatch):
    """A worker that dies before its run writes its CSV (a constructor's fault) left an earlier
    batch's runs/run_00000.csv at the run's path (--force, or a killed batch's): the row took its
    laps, frames and time. The run's output paths are cleared before it runs."""
    from simrunner.telemetry.log import RunLog, write_log

    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    ctl = tmp_path / "boom.c"
    ctl.write_text(C_CTOR_FAULT)
    stale = tmp_path / "out" / "runs" / "run_00000.csv"
    stale.parent.mkdir(parents=True)
    t_s = np.arange(1, 40) * 0.02
    write_log(RunLog(t_s=t_s, frame=np.arange(1, 40), lap=np.zeros(39, dtype=np.int64)), stale)
    res = run_batch(ctl, out_dir=tmp_path / "out", seeds=1, workers=1, plot=False, csv="all")
    row, = res.rows
    assert row["outcome"] == "controller_error" and row["frames"] == 0 and row["sim_time_s"] == 0.0, row


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_a_fault_in_a_c_programs_thread_names_its_line_as_drive_does(tmp_path, monkeypatch):
    """A thread the program started (not main()'s) dereferences NULL during the run, in the worker's
    process: its row was worker_died 'the run's process was killed by SIGSEGV at t = ...'; now
    drive's: controller_error naming the thread's file:line and function, the frames and simulated
    time from the run's CSV."""
    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    ctl = tmp_path / "t.c"
    ctl.write_text(C_THREAD_FAULT)
    res = run_batch(ctl, out_dir=tmp_path / "out", seeds=1, workers=1, plot=False, csv="all")
    row, = res.rows
    assert row["outcome"] == "controller_error", row
    assert row["message"].startswith("t.c:5: SIGSEGV: segmentation fault (in worker()), in a thread of the program's "
                                     "own (not main()'s): it killed the run's process"), row["message"]
    assert row["frames"] >= 20 and row["sim_time_s"] > 0.0


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_a_stack_overflow_in_a_c_programs_thread_names_its_line_as_drive_does(tmp_path, monkeypatch):
    """A thread the program started recurses without end, in the worker's process: the thread had no
    alternate signal stack, and the row said 'the run's process was killed by SIGSEGV at t = ...';
    now drive's: the recursing function's line, 'stack overflow', a thread of the program's."""
    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    ctl = tmp_path / "t.c"
    ctl.write_text(C_THREAD_OVERFLOW)
    res = run_batch(ctl, out_dir=tmp_path / "out", seeds=1, workers=1, plot=False, csv="all")
    row, = res.rows
    assert row["outcome"] == "controller_error", row
    assert row["message"].startswith("t.c:5: SIGSEGV: stack overflow (in recurse()), in a thread of the program's "
                                     "own (not main()'s): it killed the run's process"), row["message"]
    assert row["frames"] >= 20 and row["sim_time_s"] > 0.0

@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
@pytest.mark.parametrize("name", ["exit0.c", "exit3.c", "misuse.c"])
def test_an_end_in_a_c_constructor_at_the_load_is_told_as_drive_tells_it(tmp_path, monkeypatch, name):
    """exit(3), exit(0) or a misused Spinner call in a C constructor, as the worker loads the program's
    library before the run, ends the worker (status 70): its row was worker_died 'worker process died
    during the run (exit code 70)'; now drive's: the outcome --isolate gives, naming the call's
    file:line, and the rest of the batch runs on."""
    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    body, outcome, said = C_CTOR_ENDS[name]
    ctl = tmp_path / name
    ctl.write_text(body)
    res = run_batch(ctl, out_dir=tmp_path / "out", seeds=2, workers=1, plot=False)
    assert [(row["outcome"], row["message"]) for row in res.rows] == \
        [(outcome, f"{said}, in a constructor as the program loaded, before the first frame")] * 2
    assert [row["frames"] for row in res.rows] == [0, 0]


C_CTOR_STATE = r"""
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>
#include "spinner.h"
__attribute__((constructor)) static void at_load(void) {  /* runs as the library is loaded */
    umask(077);
    setenv("NXPCUP_C_CTOR_ENV", "1", 1);
    if (chdir("/") != 0) abort();
}
int main(void) {
    spinner_set_speed_and_servo(0.0, 0.0);
    spinner_sleep(0.1);
    return getenv("NXPCUP_C_CTOR_ENV") ? 0 : 3;  /* (its main sees what its constructor set) */
}
"""


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_what_a_c_constructor_changes_at_load_does_not_reach_the_outputs_or_the_caller(tmp_path, monkeypatch):
    """A constructor runs when the controller's library is loaded, before the run: its umask,
    setenv and chdir reached drive's outputs (written 0600, the video and the run log at the
    constructor's mask) and stayed in the process after the run (the next run of a batch
    worker). The controller's own main still sees them."""
    import os
    import stat

    from simrunner.run.runner import drive

    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("NXPCUP_C_CTOR_ENV", raising=False)
    monkeypatch.chdir(tmp_path)
    ctl = tmp_path / "ctor.c"
    ctl.write_text(C_CTOR_STATE)
    old = os.umask(0o022)
    try:
        result = drive(ctl, track="floor", time_limit_s=0.2, csv="out/d.csv", video="out/d.mp4",
                       summary="out/d.json", plot="out/d.png")
        after = (os.umask(0o022), os.getcwd(), os.environ.get("NXPCUP_C_CTOR_ENV"), os.getenv("NXPCUP_C_CTOR_ENV"))
    finally:
        os.umask(old)
    assert result.outcome == "controller_returned", result.message
    assert after == (0o022, str(tmp_path), None, None)
    modes = {p.name: oct(stat.S_IMODE(p.stat().st_mode)) for p in (tmp_path / "out").iterdir()}
    assert modes == {"d.csv": "0o644", "d.mp4": "0o644", "d.json": "0o644", "d.png": "0o644"}


C_SHORT = r"""
#include "spinner.h"
int main(void) { spinner_set_speed_and_servo(0.5, 0.0); spinner_sleep(0.1); return 0; }
"""


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_a_c_controllers_library_copies_are_removed_after_each_run(tmp_path, monkeypatch):
    """A worker's second and later runs open a private copy of the controller's library (its
    globals are fresh); the copies were removed only when the controller was collected, which
    a worker's process never did: 3 of 4 runs left a simrunner-ctrl-* folder in /tmp."""
    import tempfile

    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    ctl = tmp_path / "short.c"
    ctl.write_text(C_SHORT)
    res = run_batch(ctl, out_dir=tmp_path / "out", seeds=4, workers=1, plot=False)
    assert [r["outcome"] for r in res.rows] == ["controller_returned"] * 4
    assert sorted(p.name for p in scratch.iterdir() if p.name.startswith("simrunner-ctrl-")) == []
