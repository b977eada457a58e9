"""Running a C/C++ controller inside the simulator's process, as a coroutine.

The in-process host library (``host/spinner_host.c`` built with ``-DSPINNER_INPROC``,
:func:`~simrunner.run.native.build.inproc_library`) is loaded once per process with
``RTLD_GLOBAL``, so a controller built by simrunner binds its Spinner calls (and, through the
link's ``--wrap``, its sleeps and exits) to it. The program's ``main`` runs on a stack of its
own; a waiting call switches back here with the requests (the same messages as over the
child's pipes, answered by the same :class:`~simrunner.run.native.bridge._Session` code) and
the reply switches in again. A camera frame costs two context switches, no process hand-off.

Faults stay the controller's: the library's signal handlers (installed for the run, the
previous ones restored after it) report a SIGSEGV, SIGBUS, SIGILL, SIGFPE or SIGABRT in the
controller's code with its raw backtrace and leave the coroutine; the run ends with
``controller_error`` and the simulator goes on. A fault in its constructors (a C++ global
object's) as its library is opened, before the run, cannot be left - nothing returns out of the
loader: the handlers (installed for the open, for its thread) write its report to the
supervision's report file (:func:`~simrunner.run.supervise.current_supervision`; unsupervised,
one line to stderr) and the process dies by the signal; ``simrunner drive``'s supervisor and a
batch's pool name its file:line from that report (:mod:`simrunner.run.postmortem`). A call that
does not return there (an exit, ``spinner_fail``, a misused Spinner call) writes its report to
the same file and the process ends with status 70; the supervisor tells the run's outcome as
``--isolate`` does (:func:`~simrunner.run.postmortem.load_end`). A fault in a thread the program
started itself (not main()'s: its instruction or a frame of its stack in the program's library; a
thread of the simulator's goes to the handler before ours) cannot be left either - nothing can
leave main()'s coroutine from another thread: its report goes to the same file (handed to the host
for the run too: :func:`_report_fd`), naming that thread's line, and the process dies by the signal;
the supervisor names the line (:func:`~simrunner.run.postmortem.thread_fault`). A stack
overflow hits a guard page below the controller's stack (``ulimit -s`` bytes, 8 MB if
unlimited). A loop that never calls the API is stopped by a watchdog thread of the library after the run's ``--wall-limit``
(SIGUSR1 to the simulator's thread: the report says where). A thread the program leaves
running after its run keeps its library loaded (unloading it made the thread run on in unmapped
code, crashing the process at once, unreported): the run warns, and a later fault of that thread is
reported naming it (the host's ``stray_fault``). What it cannot contain - a
controller that overwrites the simulator's memory, or threads it leaves running - is what
``--isolate`` (the child process of :mod:`.bridge`) is for; ``simrunner drive``'s supervisor
still writes the outputs from the run log if the process dies.

Each run starts from fresh globals: the library is unloaded after the run, and if it cannot
be (C++ objects the loader keeps), the next run opens a private copy.
"""
from __future__ import annotations

import ctypes
import functools
import os
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path

from simrunner.errors import ControllerFileError, Stalled
from simrunner.run.native.bridge import ST_WHERE, _FRAME, _HDR, _ChildGone, _Session
from simrunner.run.native.build import NativeProgram, inproc_library, missing_function
from simrunner.run.supervise import current_supervision
from simrunner.run.watchdog import stall_message

REQUEST_BUFFER_BYTES = 1 << 16  # out_buf in spinner_host.c
EXIT_NO_MAIN, NO_MEMORY, BUSY = 72, 12, 16


class Busy(Exception):
    """Another run of a C controller is on in this process (in another thread)."""


@functools.lru_cache(maxsize=None)
def _api(path: str):
    """The host library, loaded once per process (a second copy would split the API state
    between the copies the controllers bind to and the one resumed)."""
    lib = ctypes.CDLL(path, mode=os.RTLD_GLOBAL | os.RTLD_NOW)
    c = ctypes
    for name, res, args in (
            ("spinner_inproc_open", c.c_void_p, [c.c_char_p, c.c_int]),
            ("spinner_inproc_error", c.c_char_p, []),
            ("spinner_inproc_close", c.c_int, [c.c_void_p]),
            ("spinner_inproc_threads", c.c_int, [c.c_void_p]),
            ("spinner_inproc_early", c.c_int, [c.c_void_p]),
            ("spinner_inproc_requests", c.c_void_p, []),
            ("spinner_inproc_exit_code", c.c_int, []),
            ("spinner_inproc_gone", c.c_int, []),
            ("spinner_inproc_pending", c.c_long, []),
            ("spinner_inproc_start", c.c_int, [c.c_void_p, c.c_int, c.POINTER(c.c_char_p), c.c_double, c.c_int]),
            ("spinner_inproc_resume", c.c_long, [c.c_char_p, c.c_size_t]),
            ("spinner_inproc_resume_image", c.c_long, [c.c_char_p, c.c_size_t]),
            ("spinner_inproc_finish", None, [])):
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = res, args
    lib.view = (c.c_char * REQUEST_BUFFER_BYTES).from_address(lib.spinner_inproc_requests())
    lib.frame_view = memoryview(lib.view)[:_FRAME.size]  # a camera frame's requests, in place
    # the per-frame calls: through PyDLL (it keeps the interpreter lock: a switch into the
    # controller is shorter than releasing it) with ctypes' own conversions (bytes, int)
    py = ctypes.PyDLL(path, mode=os.RTLD_GLOBAL | os.RTLD_NOW)
    lib.resume, lib.resume_image = py.spinner_inproc_resume, py.spinner_inproc_resume_image
    lib.resume.restype = lib.resume_image.restype = c.c_long
    return lib


@functools.lru_cache(maxsize=1)
def host_library() -> tuple[str, object]:
    """(path, API) of the in-process host library, built and loaded once per process."""
    path = str(inproc_library())
    return path, _api(path)


def _is_loaded(path: Path) -> bool:
    """Whether ``path`` is still mapped (an earlier run's library the loader kept)."""
    try:
        handle = ctypes.CDLL(str(path), mode=os.RTLD_NOLOAD | os.RTLD_NOW)
    except OSError:
        return False
    import _ctypes

    _ctypes.dlclose(handle._handle)  # the reference RTLD_NOLOAD took
    return True


def _report_fd() -> int:
    """Where the host writes the report of what ends the simulator's process with the program: a
    fault, an exit, spinner_fail or a misused call in the program's constructors as its library is
    opened (the process then dies by the signal, or ends with status 70), or a fault in a thread of
    the program's own during its run (it dies by the signal): the supervision's report file, which
    its supervisor reads (:mod:`simrunner.run.postmortem`); -1 unsupervised (a line on stderr)."""
    supervision = current_supervision()
    if supervision is None:
        return -1
    try:
        supervision.report.flush()  # (the host writes at the file's offset, past what is there)
        return supervision.report.fileno()
    except (AttributeError, OSError, ValueError):  # no file under it (closed, in memory)
        return -1


class OpenedProgram:
    """A controller library opened for one run (a private copy if the original is still
    loaded from an earlier run, removed on :meth:`close`)."""

    def __init__(self, api, program: NativeProgram):
        self.api = api
        self.copy_dir: str | None = None
        path = Path(program.library)
        if _is_loaded(path):  # its globals are an earlier run's: use a fresh copy
            self.copy_dir = tempfile.mkdtemp(prefix="simrunner-ctrl-")
            copy = Path(self.copy_dir) / path.name
            shutil.copyfile(path, copy)
            path = copy
        self.path = path
        self.handle = api.spinner_inproc_open(str(path).encode(), _report_fd())
        if not self.handle:
            err = api.spinner_inproc_error().decode("utf-8", "replace")
            self.close()
            lib = ", ".join(map(str, program.sources)) or str(program.library)
            raise ControllerFileError(missing_function(program, err) or f"{lib}: cannot be loaded ({err})")
        # its constructors called the API as it was loaded, before any run (a global object of a
        # kit's driver classes): it runs in a child process (controller.NativeController)
        self.early = bool(api.spinner_inproc_early(self.handle))

    def close(self) -> None:
        """Unload it, unless threads its program started still run (their code must stay mapped:
        the host keeps it loaded, and its private copy stays, for a fault of theirs to be named)."""
        if getattr(self, "handle", None):
            kept = self.api.spinner_inproc_close(self.handle) > 0
            self.handle = None
            if kept:
                return
        if self.copy_dir is not None:
            shutil.rmtree(self.copy_dir, ignore_errors=True)
            self.copy_dir = None


class InprocSession(_Session):
    """One run of a controller in this process (module docstring): the transport of
    :class:`_Session` is a context switch instead of two pipes."""

    def __init__(self, ctrl, spinner, opened: OpenedProgram, host_path: str):
        self.opened, self.api, self.host_path = opened, opened.api, host_path
        self._resume, self._view = self.api.resume, self.api.view
        self._resume_image, self._frame_view = self.api.resume_image, self.api.frame_view
        self.proc = None
        self._pending = b""
        self._gone = False
        super().__init__(ctrl, spinner, None)

    def _setup_transport(self, child) -> None:
        self.rfd = self.wfd = -1

    # -- transport ---------------------------------------------------------------------
    def _readable(self, deadline: float) -> bool:
        return True  # a resume always returns (the library's watchdog bounds it)

    def _recv(self) -> bytes:
        if self._gone:
            raise _ChildGone()
        data, self._pending = self._pending, b""
        n = self._resume(data, len(data))
        if n < 0:
            n = self._finished_with(n)
        return self._view[:n]

    def _finished_with(self, n: int) -> int:
        """The controller ended during a resume that returned ``n`` (< 0): the count of its
        last requests (a fault's report, say); raises _ChildGone when there are none."""
        self._gone = True
        n = -n - 1
        if n == 0:
            raise _ChildGone()
        return n

    def _exchange(self, img) -> bytes | memoryview:
        """A camera frame in one switch: the image goes in as it is (the host makes the reply's
        header) and a frame's usual requests are read where the host wrote them (a view of
        its buffer, valid until the next resume: :meth:`_serve` copies what it keeps)."""
        if self._pending or self._gone:  # replies queued before (a refused command): in order
            return super()._exchange(img)
        data = img.tobytes()
        n = self._resume_image(data, len(data))
        if n < 0:
            return self._view[:self._finished_with(n)]
        return self._frame_view if n == _FRAME.size else self._view[:n]

    def _reply(self, data: bytes) -> None:
        self._pending = self._pending + data if self._pending else data

    def _ask_where(self) -> None:
        if self.api.spinner_inproc_gone():  # it ended already (its watchdog's report, say): the
            self._gone = True               # requests again, in case the stall interrupted them
            self._buf, self._pos = self.api.view[:self.api.spinner_inproc_pending()], 0
        else:
            self._pending = _HDR.pack(ST_WHERE, 0)  # the waiting call reports where it is

    def _fault(self, report: str) -> None:
        """A report of the library's watchdog (signal SIGUSR1) ends the run as stalled."""
        if report.startswith(f"signal {int(signal.SIGUSR1)}\n"):
            clock = self.spinner._clock
            idle = time.monotonic() - clock.last_progress_wall_s
            raise Stalled(stall_message(idle, "", clock.stall_limit_s or idle, clock.in_interrupt))  # run() adds where
        super()._fault(report)

    # -- the run -----------------------------------------------------------------------
    def run(self) -> None:
        sys.stdout.flush()
        sys.stderr.flush()
        name = self.ctrl.program.name
        argv = [name.encode(), *(a.encode() for a in self.ctrl.args)]
        arr = (ctypes.c_char_p * (len(argv) + 1))(*argv, None)
        stall_s = getattr(self.spinner._clock, "stall_limit_s", None) or 0.0
        rc = self.api.spinner_inproc_start(self.opened.handle, len(argv), arr, float(stall_s), _report_fd())
        if rc == BUSY:
            raise Busy()
        if rc == EXIT_NO_MAIN:
            self.opened.close()
            prog = self.ctrl.program
            lib = ", ".join(map(str, prog.sources)) if prog.sources else str(prog.library)
            raise ControllerFileError(f"{lib}: no main() function defined")
        if rc == NO_MEMORY:
            self.opened.close()
            raise ControllerFileError(f"{name}: no memory for the controller's stack")
        self._argv = arr  # alive while the program runs
        super().run()

    def _user_modules(self) -> set[str]:
        return {str(self.opened.path)}

    def _host(self) -> str:
        return self.host_path

    def _wait(self) -> int:
        return self.api.spinner_inproc_exit_code()

    def _kill(self) -> None:
        pass  # the coroutine is left (and its stack freed) in _close

    def _close(self) -> None:
        self.api.spinner_inproc_finish()
        self.ctrl.spent(self.opened)  # unloaded after the run (NativeController)
        live = self.api.spinner_inproc_threads(self.opened.handle) if self.opened.handle else 0
        if live:
            self.spinner._s.warn_once("inproc-threads", left_threads_warning(live))


def left_threads_warning(live: int) -> str:
    """The run's warning when ``live`` threads the C/C++ program started still run at its end."""
    return (f"the C/C++ program left {live} thread{'s' if live > 1 else ''} running (not waited for): its "
            "library stays loaded in this process while they run, and a fault of theirs ends the process; join "
            "them before main() returns, or run the program with --isolate")
