"""Turning a C controller's raw fault report into file:line: :func:`describe_fault`.

The host program (``host/spinner_host.c``) reports a fault as text: ``signal N``, ``message
TEXT``, optionally ``pc ADDR`` (the faulting instruction) and one ``frame ADDR OFFSET
PATH<TAB>SYMBOL`` line per return address (glibc ``backtrace`` + ``dladdr``); a Spinner call
from a thread of the program's own is that thread's frames, then ``noticed ...`` lines (as
``frame`` lines): main()'s thread's backtrace at its next call, which reported it. A fault in a
thread the program started itself (not main()'s) has a ``thread program`` line
(:attr:`Fault.in_thread`); in the simulator's process it is written, after a ``thread-fault
LIBRARY`` and a ``host PATH`` line, to the supervision's report file, read once the process has
died of it (:func:`thread_fault_report`). A fault in a
program's constructors as the in-process host opens its library is written, after a
``load-fault LIBRARY`` and a ``host PATH`` line, to the supervision's report file, read once the
process has died (:func:`load_fault_report`); a program that ends there (an exit, spinner_fail,
a misused call in a constructor) writes the same after a ``load-end LIBRARY`` line, with an
``exit NAME STATUS`` line for an exit (:func:`load_end_report`). Frames in the controller's own
library are symbolised with its debug info by ``addr2line`` (binutils,
part of ``build-essential``); without it, frames keep their symbol names only. The builds
write DWARF 4 (``build.COMMON_FLAGS``): binutils 2.40 names the wrong file for some DWARF 5
lines (a header's function as the source file at the header's line).
"""
from __future__ import annotations

import bisect
import os
import shutil
import signal
import subprocess
from dataclasses import dataclass

IN_CONSTRUCTOR = "in a constructor as the program loaded"
"""Where a program's end was when it was in a constructor as its library loaded (the run's message
adds it: :data:`simrunner.run.postmortem.AT_LOAD` in process, this alone isolated)."""

SIGNAL_TEXT = {
    signal.SIGSEGV: "segmentation fault (invalid memory access)",
    signal.SIGBUS: "bus error (invalid memory access)",
    signal.SIGILL: "illegal instruction",
    signal.SIGFPE: "arithmetic exception (integer division by zero)",
    signal.SIGABRT: "aborted (abort() or a failed assert)",
}


@dataclass(frozen=True)
class Frame:
    """One stack frame: ``function`` name, ``file``/``line`` (None without debug info) and
    the ``module`` it is in."""

    function: str
    file: str | None
    line: int | None
    module: str

    def text(self) -> str:
        where = f"{self.file}:{self.line}" if self.file else f"in {os.path.basename(self.module)}"
        return f"{self.function or '??'} at {where}" if self.file else f"{self.function or '??'} {where}"


@dataclass(frozen=True)
class Fault:
    """A parsed report: ``signal`` (0 for a misused Spinner call, SIGUSR1 for a stalled
    loop's position), ``message`` and the user's ``frames`` (innermost first). ``noticed``: where
    the thread running main() noticed a fault of another thread's (a Spinner call from a thread
    of the program's own, whose frames ``frames`` are), else empty. ``in_thread``: the fault was
    in a thread the program started itself, not main()'s (its frames are that thread's)."""

    signal: int
    message: str
    frames: tuple[Frame, ...]
    noticed: tuple[Frame, ...] = ()
    in_thread: bool = False

    @property
    def location(self) -> Frame | None:
        """The innermost frame with a file and line in the user's code (not in the simulator's
        headers and kit libraries: an exception thrown by ``spinner.hpp`` names the call that
        caused it), else the innermost with a file, if any."""
        return _location(self.frames)

    @property
    def called(self) -> Frame | None:
        """The function of the simulator's (a kit's, ``spinner.hpp``'s) that :attr:`location`
        called, where the fault is inside one (None: the location is the innermost frame)."""
        loc = self.location
        i = next((k for k, f in enumerate(self.frames) if f is loc), 0)
        inner = self.frames[i - 1] if i > 0 else None
        return inner if inner is not None and inner.file and _ours(inner.file) else None

    @property
    def noticed_at(self) -> Frame | None:
        """:attr:`location` of :attr:`noticed` (None without)."""
        return _location(self.noticed)

    def where(self) -> str:
        loc = self.location
        return f"{loc.file}:{loc.line}" if loc else ""


def _location(frames: tuple[Frame, ...]) -> Frame | None:
    with_file = [f for f in frames if f.file]
    return next((f for f in with_file if not _ours(f.file)), with_file[0] if with_file else None)


_NATIVE_DIR = os.path.dirname(os.path.abspath(__file__))  # the simulator's headers and kits


def _ours(path: str) -> bool:
    """``path`` is one of the simulator's own sources (simrunner/run/native/...)."""
    try:
        return os.path.commonpath([os.path.abspath(path), _NATIVE_DIR]) == _NATIVE_DIR
    except ValueError:
        return False


def _display_path(path: str) -> str:
    try:
        rel = os.path.relpath(path)
    except ValueError:
        return path
    return rel if not rel.startswith("..") else path


def _line_files(module: str) -> list[tuple[int, int, str]] | None:
    """The line table's ``(start, end, file name)`` ranges of ``module`` as readelf decodes them
    (``readelf -W --debug-dump=decodedline``: binutils' own DWARF reader, not bfd's), sorted; None
    where readelf is missing or fails. binutils 2.40's addr2line reads a DWARF 5 line table's
    file 1 as the compilation unit's source (GCC 12 writes DWARF 5 by default): a function of a
    header was named as the .c file at the header's line, in a library built elsewhere (ours are
    built with -gdwarf-4); readelf names the header."""
    tool = shutil.which("readelf")
    if tool is None:
        return None
    try:
        proc = subprocess.run([tool, "-W", "--debug-dump=decodedline", module], capture_output=True,
                              text=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if proc.returncode != 0:
        return None
    ranges, last = [], None  # last: (address, name) of the row before, in this sequence
    for line in proc.stdout.splitlines():
        parts = line.split()
        if len(parts) < 3 or not parts[2].startswith("0x"):
            continue
        try:
            address = int(parts[2], 16)
        except ValueError:
            continue
        if last is not None and address > last[0]:
            ranges.append((last[0], address, last[1]))
        last = None if parts[1] == "-" else (address, parts[0])  # "-": the sequence's end
    ranges.sort()
    return ranges


def _line_file(ranges: list[tuple[int, int, str]], offset: int) -> str | None:
    """The file name the line table gives ``offset``."""
    i = bisect.bisect_right(ranges, (offset, float("inf"), "")) - 1
    return ranges[i][2] if i >= 0 and ranges[i][0] <= offset < ranges[i][1] else None


def _addr2line(module: str, offsets: list[int]) -> dict[int, list[tuple[str, str | None, int | None]]]:
    """offset -> [(function, file, line)] innermost first (inlined calls expanded); the innermost
    file as the line table names it (:func:`_line_files`) where addr2line names another."""
    tool = shutil.which("addr2line")
    if tool is None or not offsets:
        return {}
    try:
        proc = subprocess.run([tool, "-e", module, "-f", "-C", "-i", "-a",
                               *(hex(o) for o in sorted(set(offsets)))], capture_output=True, text=True,
                              timeout=20)
    except (OSError, subprocess.TimeoutExpired):
        return {}
    out: dict[int, list] = {}
    cur: list | None = None
    lines = proc.stdout.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("0x") and (i + 1 >= len(lines) or not lines[i + 1].startswith("0x")):
            cur = out[int(line, 16)] = []
            i += 1
            continue
        if cur is not None and i + 1 < len(lines):
            func, loc = line, lines[i + 1].split(" (discriminator")[0]
            path, _, num = loc.rpartition(":")
            ok = path and path != "??" and num.isdigit() and num != "0"
            cur.append((func if func != "??" else "", _display_path(path) if ok else None,
                        int(num) if ok else None))
            i += 2
            continue
        i += 1
    ranges = None
    for offset, frames in out.items():
        if not frames or frames[0][1] is None:
            continue
        if ranges is None:
            ranges = _line_files(module) or []
        name = _line_file(ranges, offset)
        func, path, num = frames[0]
        if name and os.path.basename(name) != os.path.basename(path):
            beside = os.path.join(os.path.dirname(path), name)  # (a header beside its .c file)
            frames[0] = (func, _display_path(beside) if os.path.exists(beside) else name, num)
    return out


def no_line_where(module: str, offset: int, function: str = "") -> str:
    """Where ``offset`` in ``module`` (a library without debug information: no file:line) is, as
    far as its symbol table tells: ``libx.so+0x1153 (in tick(); no debug information in libx.so:
    build it with -g for its file:line)`` (``function``: addr2line's name there, "" for none)."""
    name = _display_path(module)
    called = f"in {function if function.endswith(')') else function + '()'}; " if function else ""
    return f"{name}+0x{offset:x} ({called}no debug information in {name}: build it with -g for its file:line)"


def parse_report(text: str, user_modules: set[str], host: str) -> Fault:
    """A :class:`Fault` from the host's report; frames of ``user_modules`` get file:line.

    Handler and host frames above the fault are dropped; the frames below the controller's
    ``main`` (the host starting it) are cut. ``noticed`` lines (as ``frame`` lines) are main()'s
    thread's backtrace where it noticed another thread's misuse (:attr:`Fault.noticed`); a ``thread``
    line says the fault was a thread's of the program's own (:attr:`Fault.in_thread`)."""
    sig, message, pc, raw, noticed, in_thread = 0, "", None, [], [], False
    for line in text.splitlines():
        key, _, rest = line.partition(" ")
        if key == "signal":
            sig = int(rest or 0)
        elif key == "message":
            message = rest
        elif key == "thread":
            in_thread = True
        elif key == "pc":
            pc = int(rest, 16)
        elif key in ("frame", "noticed"):
            addr, off, rest2 = (rest.split(" ", 2) + ["", ""])[:3]
            path, _, sym = rest2.partition("\t")
            (raw if key == "frame" else noticed).append((int(addr, 16), int(off, 16), path, sym))
    user = {os.path.realpath(m) for m in user_modules}
    host_real = os.path.realpath(host)
    # (offset for symbolising, path, symbol): return addresses point after their call
    frames: list[tuple[int, str, str]] = []
    if pc is not None:
        idx = next((i for i, f in enumerate(raw) if f[0] == pc), None)
        if idx is None:
            hit = next((f for f in raw if f[0] == pc), None)
            frames = [(hit[1], hit[2], hit[3])] if hit else []
        else:
            first = raw[idx]
            frames = [(first[1], first[2], first[3])] + [(o - 1, p, s) for _, o, p, s in raw[idx + 1:]]
    else:
        frames = _below_host(raw, host_real)
    # (another thread's frames, when main()'s noticed them or it faulted: its start in libc is cut too)
    return Fault(sig, message, _symbolised(frames, user, host_real, thread=bool(noticed) or in_thread),
                 _symbolised(_below_host(noticed, host_real), user, host_real), in_thread)


def _below_host(raw: list[tuple[int, int, str, str]], host_real: str) -> list[tuple[int, str, str]]:
    """The frames of ``raw`` below its innermost host frames (the report's own and the Spinner
    call), each with the offset of its call (a return address points after it)."""
    rest = list(raw)
    while rest and os.path.realpath(rest[0][2]) == host_real:
        rest.pop(0)
    return [(o - 1, p, s) for _, o, p, s in rest]


def _symbolised(frames: list[tuple[int, str, str]], user: set[str], host_real: str,
                thread: bool = False) -> tuple[Frame, ...]:
    """:class:`Frame` s of ``(offset, path, symbol)`` frames: the user's with file:line.
    ``thread``: the frames of a thread the program started (all after its outermost user frame,
    the thread's start, are cut)."""
    # cut below the controller's main: the frames after the last user frame (host frames between
    # user frames stay: an interrupt handler, a kit's hook the host calls, ran inside a call)
    reals = [os.path.realpath(f[1]) if f[1] and f[1] != "?" else f[1] for f in frames]
    last_user = max((i for i, real in enumerate(reals) if real in user), default=-1)
    kept = []
    for f, real in zip(frames, reals):
        if last_user >= 0 and len(kept) > last_user and (real == host_real or thread):
            break
        kept.append((f[0], f[1], f[2], real in user))
    by_module: dict[str, list[int]] = {}
    for off, path, _, is_user in kept:
        if is_user:
            by_module.setdefault(path, []).append(off)
    symbols = {m: _addr2line(m, offs) for m, offs in by_module.items()}
    out: list[Frame] = []
    for off, path, sym, is_user in kept:
        found = symbols.get(path, {}).get(off) if is_user else None
        if found:
            out.extend(Frame(fn or sym, file, line, path) for fn, file, line in found)
        else:
            out.append(Frame(sym, None, None, path))
    return tuple(out)


def _what(fault: Fault) -> str:
    if not fault.signal:
        return fault.message
    text = SIGNAL_TEXT.get(fault.signal, f"signal {fault.signal}")
    return fault.message if fault.message.startswith("stack overflow") else text


def format_traceback(fault: Fault, program: str) -> str:
    """The traceback text (innermost frame first, repeated frames folded); then, for another
    thread's misuse, main()'s thread's where it noticed it."""
    what = _what(fault) + (f", {IN_THREAD}" if fault.in_thread else "")
    lines = [f"C controller {program}: {what}", "C backtrace (innermost first):", *_frame_lines(fault.frames)]
    loc = fault.location
    if loc is None:
        lines.append("(no file:line: compile with debug info, -g, and install binutils for addr2line)")
    if fault.noticed:
        lines += [f"{_NOTICED[0].upper()}{_NOTICED[1:]} (innermost first):", *_frame_lines(fault.noticed)]
    return "\n".join(lines) + "\n"


_NOTICED = "noticed by main()'s thread at its next call"

IN_THREAD = "in a thread of the program's own (not main()'s)"
"""Where a fault of :attr:`Fault.in_thread` was, as its message says it."""


def _frame_lines(frames: tuple[Frame, ...]) -> list[str]:
    lines: list[str] = []
    prev, repeat = None, 0
    for i, f in enumerate(frames):
        t = f.text()
        if t == prev:
            repeat += 1
            continue
        if repeat:
            lines.append(f"    ... the frame above {repeat} more time(s)")
            repeat = 0
        lines.append(f"  #{i} {t}")
        prev = t
        if len(lines) > 38:
            lines.append("    ...")
            break
    if repeat:
        lines.append(f"    ... the frame above {repeat} more time(s)")
    return lines


def _function(frame: Frame) -> str:
    # (a C++ function's name comes demangled with its parameters: "handler()", "Car::step(int)")
    return frame.function if frame.function.endswith(")") else f"{frame.function}()"


def fault_message(fault: Fault) -> str:
    """One line: ``file:line: what happened in function()``; for another thread's misuse, the
    kit's or ``spinner.hpp``'s function it called there (``(in worker(), calling TFC_SetServo())``)
    and where main()'s thread noticed it after that (``; noticed by main()'s thread at its next
    call, file:line (in function())``); for a fault of a thread the program started, that it was
    (``t.c:5: SIGSEGV: segmentation fault (in worker()), in a thread of the program's own (not
    main()'s)``)."""
    what = _what(fault).split(" (")[0] if fault.signal else fault.message
    name = f"SIG{signal.Signals(fault.signal).name[3:]}: " if fault.signal in SIGNAL_TEXT else ""
    loc, noticed = fault.location, fault.noticed_at
    after = f"; {_NOTICED}, {noticed.file}:{noticed.line} (in {_function(noticed)})" if noticed else ""
    after += f", {IN_THREAD}" if fault.in_thread else ""
    if loc is None:
        return f"{name}{what}{after}"
    called = fault.called if fault.noticed else None
    calling = f", calling {_function(called)}" if called else ""
    return f"{loc.file}:{loc.line}: {name}{what} (in {_function(loc)}{calling}){after}"


def describe_fault(report: str, user_modules: set[str], host: str, program: str) -> tuple[str, str]:
    """``(one line, traceback text)`` of the host's raw ``report``: :func:`fault_message` and
    :func:`format_traceback` of :func:`parse_report` (``program``: the name the traceback gives).
    Without a frame with a file and line, the line names the innermost frame's function and
    module."""
    fault = parse_report(report, user_modules, host)
    line = fault_message(fault)
    if fault.location is None and fault.frames:
        line = f"{line} (in {fault.frames[0].text()})"
    return line, format_traceback(fault, program)


LOAD_FAULT = "load-fault "
"""The first line of the in-process host's report of a fault as a program's library loads."""

THREAD_FAULT = "thread-fault "
"""The first line of the in-process host's report of a fault in a thread the program started."""

STRAY = "stray\n"
"""The line a ``thread-fault`` record's report starts with when the thread was an earlier run's
program's, left running after its run (its library kept loaded for it), not the run's."""

LOAD_END = "load-end "
"""The first line of the in-process host's report of a program that ended as its library loaded
(exit, _exit, _Exit or quick_exit, spinner_fail, a misused Spinner call in a constructor)."""


def load_fault_report(dump: str) -> tuple[str, str, str] | None:
    """``(library, host, report)`` of the in-process host's report of a fault in a program's
    constructors as its library was opened (``load-fault LIBRARY``, ``host PATH``, then the
    report) in ``dump`` (a supervision's report file), or None when there is none."""
    return _load_record(dump, LOAD_FAULT)


def thread_fault_report(dump: str) -> tuple[str, str, str] | None:
    """``(library, host, report)`` of the in-process host's report of a fault in a thread the
    program started itself (``thread-fault LIBRARY``, ``host PATH``, then the report, which has a
    ``thread program`` line) in ``dump`` (a supervision's report file), or None when there is
    none."""
    return _load_record(dump, THREAD_FAULT)


def load_end_report(dump: str) -> tuple[str, str, str] | None:
    """``(library, host, report)`` of the in-process host's report of a program that ended in its
    constructors as its library was opened (``load-end LIBRARY``, ``host PATH``, then an ``exit
    NAME STATUS`` line for an exit and the report: the message, the backtrace) in ``dump``, or
    None when there is none."""
    return _load_record(dump, LOAD_END)


def _load_record(dump: str, tag: str) -> tuple[str, str, str] | None:
    at = dump.find(tag)
    while at > 0 and dump[at - 1] != "\n":
        at = dump.find(tag, at + 1)
    if at < 0:
        return None
    head, _, rest = dump[at + len(tag):].partition("\n")
    key, _, host = rest.partition("\n")[0].partition(" ")
    if key != "host" or not head:
        return None
    return head, host, rest.partition("\n")[2]
