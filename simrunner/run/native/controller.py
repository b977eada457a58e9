"""A C/C++ controller as a ``main(spinner)`` callable: :class:`NativeController` runs a built
program in this process (:mod:`.inproc`) or in a child process (:mod:`.bridge`), and
:func:`load_native` builds one from sources. The runner calls it as any controller."""
from __future__ import annotations

import sys
from pathlib import Path

from simrunner.run.native.bridge import _Child, _cpu_getter, _Session
from simrunner.run.native.build import NativeProgram, host_program
from simrunner.run.native.inproc import Busy, InprocSession, OpenedProgram, host_library


class NativeController:
    """``main(spinner)`` for a built :class:`NativeProgram` (see the module docstring).

    A program simrunner built runs in this process (:mod:`.inproc`) unless
    ``program.isolate``; a prebuilt library (its sleeps are not linked to the simulated
    ones) and an isolated program run in a child process. The library is opened (or the
    child started) here, ahead of the run."""

    def __init__(self, program: NativeProgram, args: tuple[str, ...] = (),
                 isrs: tuple[tuple[str, float], ...] = ()):
        self.program = program
        self.args = tuple(args)
        self.isrs = tuple(isrs) or program.isrs  # --isr: (function name, period s), timer interrupts
        self.inproc = bool(program.sources) and not program.isolate and sys.platform.startswith("linux")
        self.host = self.getcpu = None
        self._spent: list = []  # libraries of finished runs, unloaded before the next one
        if self.inproc:
            self.host_path, self.api = host_library()  # built (once, cached) before the run
            self._ready = self._open()
        if not self.inproc:
            self._ready = self._child()

    def _open(self) -> OpenedProgram | None:
        """The library opened in this process, or None when its constructors called the API as it
        was loaded (before the run, where nothing can be asked): then it runs in a child process,
        where they run with the run there, as on the board before main() (``inproc`` cleared)."""
        opened = OpenedProgram(self.api, self.program)
        if not opened.early:
            return opened
        opened.close()
        self.inproc = False
        return None

    def _child(self) -> _Child:
        if self.host is None:
            self.host = host_program()  # built (once, cached)
            self.getcpu = _cpu_getter()
        return _Child(self.host, self.program, self.args)

    def __call__(self, spinner) -> None:
        ready, self._ready = self._ready, None
        if self.inproc and ready is None:
            self._unload()
            ready = self._open()
        if self.inproc:
            try:
                InprocSession(self, spinner, ready, self.host_path).run()
                return
            except Busy:  # a run in another thread has the in-process host: use a child
                self.spent(ready)
            ready = None
        _Session(self, spinner, ready or self._child()).run()

    def spent(self, opened) -> None:
        """A run's library, to unload once the run is over (not in its time)."""
        self._spent.append(opened)

    def _unload(self) -> None:
        while self._spent:
            self._spent.pop().close()

    def close(self) -> None:
        """Unload the runs' libraries (and remove their private copies), and one opened for a
        run that never started. Called when its runs are over (drive() calls it at the end of
        its run; a batch worker's process ends without collecting it)."""
        if getattr(self, "inproc", False):
            self._unload()
            if getattr(self, "_ready", None) is not None:  # None too when opening it failed
                self._ready.close()
                self._ready = None

    def __del__(self) -> None:
        self.close()


def load_native(sources: list[str | Path] | NativeProgram, args: tuple[str, ...] = (),
                isrs: tuple[tuple[str, float], ...] = ()) -> NativeController:
    """A controller callable from C/C++ sources (built, cached) or a :class:`NativeProgram`;
    ``isrs``: its functions to call as timer interrupts, ``(name, period_s)`` each."""
    from simrunner.run.native.build import build_program

    program = sources if isinstance(sources, NativeProgram) else build_program(list(sources))
    return NativeController(program, args, isrs)
