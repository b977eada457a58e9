"""Loading a controller: a Python file defining ``main(spinner)``, or a callable.

:func:`load_controller` checks the file (one-line :class:`ControllerFileError` for a missing,
non-Python or syntactically wrong file) and compiles it; :meth:`Controller.loaded` executes it
in its own module, with its folder first on ``sys.path`` (so ``import helper`` finds the
controller's own modules) and undoes both afterwards, so a later run of another folder's
``helper.py`` does not get this one. :func:`user_traceback` keeps the user's frames only.
"""
from __future__ import annotations

import ast
import contextlib
import functools
import inspect
import os
import sys
import threading
import traceback
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from simrunner.errors import ControllerFileError
from simrunner.run.delayloops import DelayLoop, delay_warnings
from simrunner.run.hostclock import (ClockRead, clock_warnings, module_names, own_module_clock_reads,
                                     python_clock_reads)
from vehicle.userfiles import read_user_text

PACKAGE_DIR = str(Path(__file__).resolve().parent.parent)  # simrunner/: not the user's frames
MODULE_NAME = "simrunner_controller"

MainFn = Callable[[object], object]


@dataclass(frozen=True)
class Controller:
    """A loaded-but-not-run controller: compiled ``code`` of ``path``, or a callable ``main``."""

    path: Path | None
    code: types.CodeType | None
    main: MainFn | None
    user_file: str | None  # file whose frames are the user's (watchdog, tracebacks)
    owned: bool = False  # main was made here (a C/C++ program loaded), not the caller's to keep
    clock_reads: tuple[ClockRead, ...] = ()  # where it reads the computer's clock (hostclock), warned
    delay_loops: tuple[DelayLoop, ...] = ()  # its empty counting loops (C/C++: delayloops), warned

    def load_warnings(self) -> list[str]:
        """What was found in its code before a run, worded (said first, with the run's warnings): where
        it reads the computer's clock, then where it delays with an empty counting loop."""
        return clock_warnings(self.clock_reads) + delay_warnings(self.delay_loops)

    @contextlib.contextmanager
    def loaded(self) -> Iterator[MainFn]:
        """Execute the file (its top-level code may raise: that is a controller fault) and
        yield its ``main``; ``sys.modules``/``sys.path`` are restored on exit."""
        if self.code is None:
            yield self.main
            return
        folder = str(Path(self.code.co_filename).parent)
        modules_before = set(sys.modules)
        module = types.ModuleType(MODULE_NAME)
        module.__file__ = self.code.co_filename
        sys.modules[MODULE_NAME] = module
        sys.path.insert(0, folder)
        hook = threading.excepthook
        threading.excepthook = functools.partial(_thread_excepthook, hook)
        try:
            exec(self.code, module.__dict__)
            yield controller_main(module, self.path)
        finally:
            threading.excepthook = hook
            sys.modules.pop(MODULE_NAME, None)
            _forget_modules_from(folder, set(sys.modules) - modules_before)
            if folder in sys.path:
                sys.path.remove(folder)

    def close(self) -> None:
        """Release what loading it took (a C/C++ controller's libraries and their copies),
        once its runs are over; a callable given by the caller stays the caller's."""
        if self.owned:
            self.main.close()


def load_controller(controller) -> Controller:
    """A :class:`Controller` from a file path (``.py``; ``.c``/``.cpp``/``.so``: see
    :mod:`simrunner.run.native`), a built ``NativeProgram`` or a callable ``main(spinner)``."""
    if callable(controller):
        try:
            user_file = inspect.getsourcefile(controller)
        except TypeError:
            user_file = None
        return Controller(None, None, controller, user_file)
    if not isinstance(controller, (str, Path)):  # a built C/C++ program (simrunner.run.native)
        from simrunner.run.native import NativeProgram, load_native

        if isinstance(controller, NativeProgram):
            return Controller(None, None, load_native(controller), None, owned=True,
                              clock_reads=controller.clock_reads, delay_loops=controller.delay_loops)
    path = Path(controller)
    if path.suffix != ".py":  # (the build machinery is ~7 ms to import: not for a .py file)
        from simrunner.run.native import is_native, load_native

        if is_native(path):  # C/C++ sources or a shared library: compiled (cached), run
            main = load_native([path])
            return Controller(path, None, main, None, owned=True, clock_reads=main.program.clock_reads,
                              delay_loops=main.program.delay_loops)
    code, clock_reads, imports = _compiled(str(path), str(path.resolve()), _controller_source(path))
    return Controller(path, code, None, code.co_filename,
                      clock_reads=clock_reads + own_module_clock_reads(imports, str(path)))


def compile_controller(path: str | Path) -> types.CodeType:
    """Compile a controller file; bad files raise :class:`ControllerFileError` (one line)."""
    path = Path(path)
    return _compiled(str(path), str(path.resolve()), _controller_source(path))[0]


def _controller_source(path: Path) -> str:
    """The text of a controller file; bad files raise :class:`ControllerFileError`."""
    if not path.is_file():
        raise ControllerFileError(f"{path}: no such controller file")
    if path.suffix != ".py":
        raise ControllerFileError(f"{path}: expected a Python file (.py) with main(spinner), "
                                  f"C/C++ sources (.c, .cpp) with main() or a shared library (.so)")
    return read_user_text(path, "controller", ControllerFileError, "Python")


@functools.lru_cache(maxsize=16)
def _compiled(shown: str, filename: str,
              source: str) -> tuple[types.CodeType, tuple[ClockRead, ...], tuple[str, ...]]:
    """The code of a controller file's ``source``, where it reads the computer's clock
    (:func:`~simrunner.run.hostclock.python_clock_reads`) and the modules it imports
    (:func:`~simrunner.run.hostclock.module_names`: its own beside it are read for their clock
    reads at each load, as they may change), parsed once; kept for the same text,
    so a batch worker's or ``--watch``'s next run of an unchanged file compiles nothing (a code
    object is immutable: each run executes it in a fresh module). ``shown``: the path as given,
    for the messages; ``filename``: the code's (tracebacks)."""
    try:
        tree = ast.parse(source, filename, "exec")
        code = compile(tree, filename, "exec")
    except SyntaxError as exc:  # (compile finds some past the parser: `return` outside a function)
        raise ControllerFileError(f"{shown}:{exc.lineno}: syntax error: {exc.msg}") from None
    except ValueError as exc:  # e.g. null bytes
        raise ControllerFileError(f"{shown}: not a Python file ({exc})") from None
    return code, python_clock_reads(tree, source, shown), module_names(tree)


def _thread_excepthook(hook, args) -> None:
    """A controller thread's exception: one that ended the run and is its outcome already (a
    Spinner call from that thread) is not printed again as the thread's traceback, through the
    simulator's frames; any other goes to ``hook``."""
    if not getattr(args.exc_value, "ends_the_run", False):
        hook(args)


def controller_main(module: types.ModuleType, path: Path | None) -> MainFn:
    """The module's ``main``, checked to take one argument."""
    main = getattr(module, "main", None)
    if not callable(main):
        import difflib

        own = [n for n, v in vars(module).items() if inspect.isfunction(v) and v.__module__ == module.__name__]
        near = difflib.get_close_matches("main", own, n=1, cutoff=0.6)
        hint = f" (did you mean {near[0]}?)" if near else ""
        raise ControllerFileError(f"{path}: no main(spinner) function defined{hint}")
    try:
        inspect.signature(main).bind(object())
    except TypeError:
        raise ControllerFileError(f"{path}: main must take one argument (the Spinner)") from None
    except ValueError:  # no signature (builtins): let the call decide
        pass
    return main


def user_traceback(exc: BaseException) -> str:
    """Traceback text of ``exc`` without the simulator's frames (the user's frames only)."""
    te = traceback.TracebackException.from_exception(exc)
    seen = set()

    def trim(t: traceback.TracebackException | None) -> None:
        while t is not None and id(t) not in seen:
            seen.add(id(t))
            t.stack = traceback.StackSummary.from_list(
                [f for f in t.stack if not f.filename.startswith(PACKAGE_DIR)
                 and not f.filename.startswith("<frozen importlib")
                 and not f.filename.startswith(contextlib.__file__)])
            trim(t.__cause__)
            t = t.__context__

    trim(te)
    return "".join(te.format())


def user_location(traceback_text: str) -> str:
    """``FILE:LINE`` (the file's name) of the innermost frame of a user traceback's text, or
    "" when it names none."""
    loc = ""
    for line in traceback_text.splitlines():
        s = line.strip()
        if s.startswith('File "') and ", line " in s:
            path = s[6:s.index('"', 6)]
            lineno = s.split(", line ")[1].split(",")[0]
            loc = f"{os.path.basename(path)}:{lineno}"
    return loc


def _forget_modules_from(folder: str, names: set[str]) -> None:
    """Unload helper modules a controller imported from its own folder."""
    for name in names:
        f = getattr(sys.modules.get(name), "__file__", None) or ""
        if f and os.path.dirname(os.path.abspath(f)) == folder:
            sys.modules.pop(name, None)
