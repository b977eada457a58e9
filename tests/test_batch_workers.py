"""simrunner batch's local workers (issue 50): forked warm from the batch's process, runs
still isolated from each other, and a worker that dies in a run reported as drive reports it."""
from __future__ import annotations

import shutil
import textwrap
import threading

import pytest

from helpers import STUCK

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
    assert threading.active_count() == 1 and choose_start_method() == "fork"
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
