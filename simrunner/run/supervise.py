"""A run under a supervisor process, so that a run whose process dies still gets its outputs.

A controller stuck inside one C-level call that holds the interpreter (``sum(range(10**13))``,
a huge regex, a C extension that never returns) lets no Python code run in its process: no
watchdog tick, no writer thread, no output writing. The hard watchdog
(:mod:`simrunner.run.watchdog`) then ends that process. Nothing in it can write the summary,
the plot or a playable video, so another process does it:

:func:`supervise` forks. The child runs the drive as usual (the caller's ``child()``: drive,
print, return the exit code), streaming its run log to disk as always (to a temporary file
when no ``--csv`` was asked for) and, should the hard watchdog fire, its stack dump to a file
of the supervisor's (:func:`current_supervision`). The parent waits (SIGTERM and SIGHUP are
passed on to the child; SIGINT reaches both from the terminal and the parent ignores it). If
the child's hard watchdog fired, the parent writes the outputs from what is on disk
(:mod:`simrunner.run.postmortem`): the run log's rows, the summary (outcome ``stalled``, the
controller's file:line from the dump), the plot and the video, rebuilt from the log; so it does
for a child a signal killed (a fault of a C/C++ program's constructors at its library's load or of
a thread of the program's own named at its line: the in-process host's report in the same file),
and for one whose C/C++ program ended in its constructors as its library loaded (the host's report;
the child's status 70).

The child dies with the parent (``PR_SET_PDEATHSIG``, Linux), so killing the command kills
the run. Only where a fork is safe and useful: the main thread, stdout and stderr real files
(:func:`can_supervise`); elsewhere callers run the drive in-process.
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Callable, Iterator


@dataclass(frozen=True)
class Supervision:
    """What a supervised run does for its supervisor: ``report`` receives the hard
    watchdog's stack dump (and the in-process C host's report of a program's fault or end at its
    library's load, or of a fault in a thread of its own); ``csv_path`` is where the run log streams when the run was asked
    for none (None: nowhere; a batch worker keeps no log of runs asked for none)."""

    report: IO[str]
    csv_path: Path | None


_SUPERVISION: contextvars.ContextVar[Supervision | None] = contextvars.ContextVar(
    "simrunner_supervision", default=None)


def current_supervision() -> Supervision | None:
    """The supervision of the runs started in this context (None: not supervised)."""
    return _SUPERVISION.get()


@contextlib.contextmanager
def supervised_by(supervision: Supervision) -> Iterator[None]:
    token = _SUPERVISION.set(supervision)
    try:
        yield
    finally:
        _SUPERVISION.reset(token)


@dataclass(frozen=True)
class ChildEnd:
    """How the supervised child ended: its exit ``code`` (128 + N when killed by signal N),
    the hard watchdog's ``report`` (empty unless it fired), the run log it streamed
    (``csv_path``), its wall and CPU time."""

    code: int
    report: str
    csv_path: Path
    wall_time_s: float
    cpu_time_s: float
    signal: int | None = None  # the signal that killed the child (not a handled end)
    csv_untouched: bool = False  # csv_path is the file that was there before the run, as it was

    def stale_log_removed(self) -> None:
        """Remove ``csv_path`` if the child never wrote it (:attr:`csv_untouched`: an earlier run's
        log, which this run's was to replace - it ended before its first row); the outputs written
        from the run log then have its header only, not that run's rows."""
        if self.csv_untouched:
            self.csv_path.unlink(missing_ok=True)

    @property
    def stuck(self) -> bool:
        """The hard watchdog ended the child (a controller stuck in one C-level call)."""
        return "Timeout (" in self.report


def can_supervise() -> bool:
    """A fork is possible and its output reaches the same files (not under click's test
    runner, whose streams are in memory)."""
    if not hasattr(os, "fork") or threading.current_thread() is not threading.main_thread():
        return False
    try:
        sys.stdout.fileno(), sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        return False
    return True


def supervise(child: Callable[[], int], csv_path: str | Path | None) -> ChildEnd:
    """Run ``child()`` (returns an exit code; may raise ``SystemExit``) in a forked process
    under :class:`Supervision`; return how it ended. ``csv_path``: the run log the child
    writes, or None (then a temporary one; the caller removes ``ChildEnd.csv_path``)."""
    if csv_path is None:
        csv = private_temp_dir("run") / "run.csv"
    else:
        csv = Path(csv_path)
    before = _file_state(csv)
    report = tempfile.TemporaryFile("w+", errors="replace")  # no name: nothing left behind
    sys.stdout.flush()
    sys.stderr.flush()
    wall0 = time.monotonic()
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:  # the child: never returns
        _child(child, report, csv, parent)
    forward = {s: signal.signal(s, lambda signum, frame: _pass_on(pid, signum))
               for s in (signal.SIGTERM, signal.SIGHUP)}
    old_int = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        _, status, usage = os.wait4(pid, 0)
    finally:
        for s, old in forward.items():
            signal.signal(s, old)
        signal.signal(signal.SIGINT, old_int)
    code = os.waitstatus_to_exitcode(status)
    with report:
        report.seek(0)  # the child wrote through the same open file
        text = report.read()
    return ChildEnd(code=128 - code if code < 0 else code, report=text, csv_path=csv,
                    wall_time_s=time.monotonic() - wall0,
                    cpu_time_s=usage.ru_utime + usage.ru_stime, signal=-code if code < 0 else None,
                    csv_untouched=before is not None and _file_state(csv) == before)


def _file_state(path: Path) -> tuple[int, int, int, int, int] | None:
    """What tells whether the file at ``path`` was written or replaced (None: there is none)."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns


def private_temp_dir(kind: str) -> Path:
    """A new temporary folder ``simrunner-KIND-PID-XXXX`` of this process; first the folders
    of earlier processes of this kind that died without removing theirs (killed by SIGKILL,
    the out-of-memory killer) are removed: those whose process is gone, older than a minute."""
    base = Path(tempfile.gettempdir())
    now = time.time()
    for old in base.glob(f"simrunner-{kind}-*-*"):
        pid = old.name[len(f"simrunner-{kind}-"):].split("-", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            os.kill(int(pid), 0)
            continue  # (its process lives: yours or another user's)
        except ProcessLookupError:
            pass
        except OSError:  # (another user's process)
            continue
        with contextlib.suppress(OSError):
            if now - old.stat().st_mtime > 60.0 and os.access(old, os.W_OK):
                shutil.rmtree(old, ignore_errors=True)
    return Path(tempfile.mkdtemp(prefix=f"simrunner-{kind}-{os.getpid()}-"))


def remove_temporary(end: ChildEnd, csv_path: str | Path | None) -> None:
    """Remove the temporary run log of a run asked for none (and its folder)."""
    if csv_path is None:
        end.csv_path.unlink(missing_ok=True)
        with contextlib.suppress(OSError):
            end.csv_path.parent.rmdir()


def _pass_on(pid: int, signum: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signum)


def _child(child: Callable[[], int], report: IO[str], csv_path: Path, parent_pid: int) -> None:
    code = 1
    try:
        die_with_parent(parent_pid)
        with supervised_by(Supervision(report, csv_path)):
            code = child()
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BrokenPipeError:  # the reader of our output went away (`simrunner drive ... | head`)
        code = 141  # as a shell reports SIGPIPE; nothing to show: the reader is gone
    except BaseException:  # noqa: BLE001 - a bug: shown like the uncaught exception it is
        import traceback

        traceback.print_exc()
        code = 1
    finally:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code)


def die_with_parent(parent_pid: int | None = None) -> None:
    """Linux: the kernel sends SIGKILL to this process when its parent dies (``drive``'s run
    process, a batch worker: a supervisor or batch killed by SIGKILL leaves nothing running;
    prctl(2), PR_SET_PDEATHSIG: sent when the parent's thread that started this process ends).
    A process whose parent died before the call ends at once: with ``parent_pid`` (the pid of
    the process that forked this one) when its parent pid is another (reparented to init or to
    a subreaper); without it (a process started by a forkserver, whose parent is the server)
    when its parent is init."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the child may outlive a killed parent
        pass
    if os.getppid() != parent_pid if parent_pid is not None else os.getppid() == 1:
        os._exit(1)  # the parent died before the call


__all__ = ["ChildEnd", "Supervision", "can_supervise", "current_supervision", "die_with_parent", "private_temp_dir",
           "remove_temporary", "supervise", "supervised_by"]
