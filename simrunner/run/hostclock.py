"""Where a controller reads the computer's clock, or seeds randomness from it.

The simulator keeps the host's clock the host's (as ROS's ``use_sim_time`` does): simulated time
passes only through the Spinner API, and the sleeps wait in it. A controller that times its loop
or its dt with ``time.monotonic()`` / ``clock_gettime`` reads the computer's clock, not the
simulated car's (a run goes many times faster than real time), and one seeded from the clock makes every run different. These are
found before the run, to be said with the run's warnings (``simrunner check`` and ``drive``):

- :func:`python_clock_reads`: from a Python controller's syntax tree (its imports' aliases
  followed: ``import time as t``, ``from time import monotonic``);
- :func:`native_clock_reads`: from a C/C++ build's object files - the calls (relocations) of the
  clock functions, each at its file:line from the debug info (``objdump -dlr``), in the user's own
  files only (not a kit's library, not the simulator's headers, not the system's).

:func:`clock_warnings` words them, one per place, the first :data:`SHOWN` and a count of the rest.
"""
from __future__ import annotations

import ast
import functools
import os
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

#: places worded one by one; the rest are counted in one more line
SHOWN = 3

#: Python's functions that read the host's clock (qualified by the module they come from)
PYTHON_CLOCKS = frozenset(
    [f"time.{name}{ns}" for name in ("time", "monotonic", "perf_counter", "process_time", "thread_time")
     for ns in ("", "_ns")]
    + ["datetime.datetime.now", "datetime.datetime.utcnow", "datetime.datetime.today", "datetime.date.today"])
#: seeding calls and generators that, without an argument (or with None), seed from the operating
#: system / the clock (Python's random module docs; NumPy's "Random Generator": ``default_rng()``
#: "pulls fresh, unpredictable entropy from the OS"); ``random.SystemRandom`` is never seeded
PYTHON_SEEDS = frozenset(["random.seed", "numpy.random.seed", "random.Random", "random.SystemRandom",
                          "numpy.random.default_rng", "numpy.random.RandomState", "numpy.random.SeedSequence",
                          "numpy.random.PCG64", "numpy.random.PCG64DXSM", "numpy.random.MT19937",
                          "numpy.random.Philox", "numpy.random.SFC64"])

#: C/C++ symbols (as the linker sees them) that read the host's clock -> their name as written
NATIVE_CLOCKS = {
    "clock_gettime": "clock_gettime", "gettimeofday": "gettimeofday", "time": "time", "clock": "clock",
    "timespec_get": "timespec_get", "ftime": "ftime",
    # libstdc++ (the Itanium C++ ABI's names; high_resolution_clock is system_clock there)
    "_ZNSt6chrono3_V212steady_clock3nowEv": "std::chrono::steady_clock::now",
    "_ZNSt6chrono3_V212system_clock3nowEv": "std::chrono::system_clock::now",
    # libc++ (clang's -stdlib=libc++)
    "_ZNSt3__16chrono12steady_clock3nowEv": "std::chrono::steady_clock::now",
    "_ZNSt3__16chrono12system_clock3nowEv": "std::chrono::system_clock::now",
}
NATIVE_SEEDS = frozenset(["srand", "srandom", "srand48", "seed48"])

_RELOCATION = re.compile(r"^\s*[0-9a-f]+: R_\w+\s+([^\s+-]+)")
_LINE = re.compile(r"^(\S.*?):(\d+)(?: \(discriminator \d+\))?$")


@dataclass(frozen=True)
class ClockRead:
    """A place (``file``:``line``) where a controller calls ``call`` (as it is written, e.g.
    ``time.monotonic()``, ``clock_gettime()``, ``srand(time(NULL))``): a read of the host's clock,
    or with ``seeds`` a seeding from it. ``python``: the advice names the Python API."""

    file: str
    line: int
    call: str
    seeds: bool = False
    python: bool = False

    def text(self) -> str:
        """The warning, as ``simrunner check`` and ``drive`` print it."""
        if self.seeds:
            api = 'spinner.param("seed", 1)' if self.python else 'spinner_param("seed", 1)'
            return f"{self.file}:{self.line}: {self.call} makes every run different: seed from {api} or a constant"
        api = "spinner.get_time()" if self.python else "spinner_get_time()"
        return (f"{self.file}:{self.line}: {self.call} reads the computer's clock, not the simulated car's (a run goes many "
                f"times faster than real time): use {api} (simulated seconds) for loop timing and dt")

    def to_json(self) -> list:
        return [self.file, self.line, self.call, self.seeds, self.python]

    @classmethod
    def from_json(cls, item: list) -> "ClockRead":
        file, line, call, seeds, python = item
        return cls(str(file), int(line), str(call), bool(seeds), bool(python))


def place_warnings(places, noun: str, what: str) -> list[str]:
    """The warnings of ``places`` (each with ``text()``, ``file`` and ``line``): one per place, the
    first :data:`SHOWN`, then ``and N more {noun}s {what} (file:line, ...)``."""
    texts = [p.text() for p in places[:SHOWN]]
    rest = places[SHOWN:]
    if rest:
        where = ", ".join(f"{p.file}:{p.line}" for p in rest[:5]) + (", ..." if len(rest) > 5 else "")
        texts.append(f"and {len(rest)} more {noun}{'s' if len(rest) > 1 else ''} {what} ({where})")
    return texts


def clock_warnings(reads: tuple[ClockRead, ...] | list[ClockRead]) -> list[str]:
    """The warnings of ``reads`` (:func:`place_warnings`)."""
    return place_warnings(reads, "place", "reading the computer's clock or seeding from it")


# -- Python ---------------------------------------------------------------------------------
def python_clock_reads(tree: ast.AST, source: str, file: str) -> tuple[ClockRead, ...]:
    """Where the module ``tree`` (parsed from ``source``, shown as ``file``) reads the host's clock
    (:data:`PYTHON_CLOCKS`, called or not: ``now = time.monotonic`` is one) or seeds a random
    generator without an argument or from the clock (:data:`PYTHON_SEEDS`); anywhere in the file,
    in ``main`` or in a function it defines. Sorted by line, one per line and call."""
    names = _imported_names(tree)
    seeded: set[int] = set()  # clock reads inside a seeding call: said as the seeding
    found: dict[tuple[int, str], ClockRead] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and _qualified(node.func, names) in PYTHON_SEEDS:
            inner = [n for arg in [*node.args, *node.keywords] for n in ast.walk(arg)
                     if _qualified(n, names) in PYTHON_CLOCKS]
            if not (node.args or node.keywords) or inner or _seeds_none(node) \
                    or _qualified(node.func, names) == "random.SystemRandom":
                seeded.update(id(n) for n in inner)
                call = ast.get_source_segment(source, node) or f"{_qualified(node.func, names)}()"
                found.setdefault((node.lineno, call), ClockRead(file, node.lineno, " ".join(call.split()),
                                                                seeds=True, python=True))
    for node in ast.walk(tree):
        qualified = _qualified(node, names)
        if qualified in PYTHON_CLOCKS and id(node) not in seeded:
            found.setdefault((node.lineno, qualified), ClockRead(file, node.lineno, f"{qualified}()", python=True))
    return tuple(sorted(found.values(), key=lambda r: (r.line, r.call)))


def _seeds_none(call: ast.Call) -> bool:
    """``call``'s seed is the constant None (``default_rng(None)``, ``random.seed(a=None)``)."""
    first = call.args[0] if call.args else next(
        (k.value for k in call.keywords if k.arg in ("seed", "a", "x", "entropy")), None)
    return isinstance(first, ast.Constant) and first.value is None


MAX_OWN_MODULES = 32
"""The controller's own modules (beside it) :func:`own_module_clock_reads` reads at most."""


def own_module_clock_reads(imports: tuple[str, ...], file: str) -> tuple[ClockRead, ...]:
    """:func:`python_clock_reads` of the controller's own modules: those it imports (``imports``:
    :func:`module_names` of the controller) and they import in turn, that are files beside it
    (``import pid``, ``from helpers.timing import dt``: ``pid.py``, ``helpers/timing.py``; the
    folder is on ``sys.path`` while it runs), shown beside ``file`` (``team/main.py`` ->
    ``team/pid.py``). Installed packages and the standard library are not the controller's; a
    module that cannot be read or parsed is skipped (the run says what is wrong with it when it
    imports it). At most :data:`MAX_OWN_MODULES` files, each parsed once for its text."""
    shown_dir = Path(file).parent
    folder = shown_dir.resolve()
    seen: set[Path] = set()
    todo = [imports]
    reads: list[ClockRead] = []
    while todo and len(seen) < MAX_OWN_MODULES:
        for name in todo.pop():
            parts = name.split(".")
            for path in (folder.joinpath(*parts).with_suffix(".py"), folder.joinpath(*parts, "__init__.py")):
                if path in seen or not path.is_file():
                    continue
                seen.add(path)
                try:
                    source = path.read_text(encoding="utf-8")
                except (OSError, UnicodeDecodeError):
                    break
                found, more = _module_scan(str(shown_dir / path.relative_to(folder)), source)
                reads += found
                todo.append(more)
                break
    return tuple(reads)


@functools.lru_cache(maxsize=64)
def _module_scan(shown: str, source: str) -> tuple[tuple[ClockRead, ...], tuple[str, ...]]:
    """A module's clock reads and :func:`module_names` (none if it does not parse)."""
    try:
        tree = ast.parse(source, shown)
    except (SyntaxError, ValueError):
        return (), ()
    return python_clock_reads(tree, source, shown), module_names(tree)


def module_names(tree: ast.AST) -> tuple[str, ...]:
    """The absolute module names ``tree`` imports (``import a.b`` -> ``a``, ``a.b``)."""
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                names += [".".join(parts[:i + 1]) for i in range(len(parts))]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            parts = node.module.split(".")
            names += [".".join(parts[:i + 1]) for i in range(len(parts))]
            names += [f"{node.module}.{alias.name}" for alias in node.names if alias.name != "*"]
    return tuple(dict.fromkeys(names))


def _imported_names(tree: ast.AST) -> dict[str, str]:
    """Local name -> what it is (``t`` -> ``time``, ``monotonic`` -> ``time.monotonic``) for the
    imports of the modules that matter here, wherever in the file they are."""
    modules = ("time", "datetime", "random", "numpy")
    names: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                top = alias.name.split(".")[0]
                if top in modules:
                    if alias.asname:
                        names[alias.asname] = alias.name
                    else:
                        names[top] = top
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.split(".")[0] in modules:
            for alias in node.names:
                if alias.name == "*":
                    for full in PYTHON_CLOCKS | PYTHON_SEEDS:
                        module, _, name = full.rpartition(".")
                        if module == node.module:
                            names[name] = full
                else:
                    names[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return names


def _qualified(node: ast.AST, names: dict[str, str]) -> str | None:
    """``node`` (a name or an attribute chain) as the dotted name it stands for, or None."""
    if isinstance(node, ast.Name):
        return names.get(node.id)
    if isinstance(node, ast.Attribute):
        base = _qualified(node.value, names)
        return None if base is None else f"{base}.{node.attr}"
    return None


# -- C/C++ ----------------------------------------------------------------------------------
def native_clock_reads(objects: list[Path], own_files: dict[str, str]) -> tuple[ClockRead, ...]:
    """Where the compiled ``objects`` (with debug info) call the host's clock (:data:`NATIVE_CLOCKS`)
    or seed from it (:data:`NATIVE_SEEDS` on the same line as a clock read), at the places in
    ``own_files`` (real path -> the name to show) only: the user's sources and headers, not a kit's
    or the system's. Empty where ``objdump`` (binutils) is missing or fails."""
    sites: dict[tuple[str, int], list[str]] = {}  # (file, line) -> the symbols called there
    for obj in objects:
        try:
            out = subprocess.run(["objdump", "-dlr", "--no-show-raw-insn", str(obj)], capture_output=True,
                                 text=True, timeout=60)
        except (OSError, subprocess.SubprocessError):
            return ()
        if out.returncode != 0:
            return ()
        where: tuple[str, int] | None = None
        for text in out.stdout.splitlines():
            reloc = _RELOCATION.match(text)
            if reloc:
                symbol = reloc.group(1).split("@")[0]
                if where is not None and (symbol in NATIVE_CLOCKS or symbol in NATIVE_SEEDS):
                    sites.setdefault(where, []).append(symbol)
                continue
            line = _LINE.match(text)
            if line:
                shown = own_files.get(os.path.realpath(line.group(1)))
                where = None if shown is None else (shown, int(line.group(2)))
            elif text.startswith("Disassembly of section "):
                where = None  # (a section's code starts with its line)
    reads = []
    for (file, number), symbols in sorted(sites.items()):
        clocks = list(dict.fromkeys(s for s in symbols if s in NATIVE_CLOCKS))
        seeders = [s for s in symbols if s in NATIVE_SEEDS]
        source = _source_line(own_files, file, number)
        if seeders and clocks:
            call = _call_text(source, seeders[0]) or (
                f"{seeders[0]}(time(NULL))" if clocks[0] == "time" else f"{seeders[0]}() from {NATIVE_CLOCKS[clocks[0]]}()")
            reads.append(ClockRead(file, number, call, seeds=True))
            continue
        for symbol in clocks:
            name = NATIVE_CLOCKS[symbol]
            if name.endswith("system_clock::now") and "high_resolution_clock" in source \
                    and "system_clock" not in source:
                name = "std::chrono::high_resolution_clock::now"
            reads.append(ClockRead(file, number, f"{name}()"))
    return tuple(reads)


def _source_line(own_files: dict[str, str], file: str, number: int) -> str:
    """Line ``number`` of the user's ``file`` (as shown), or '' when it cannot be read."""
    for real, shown in own_files.items():
        if shown == file:
            try:
                lines = Path(real).read_text(encoding="utf-8", errors="replace").splitlines()
            except OSError:
                return ""
            return lines[number - 1] if 0 < number <= len(lines) else ""
    return ""


def _call_text(line: str, name: str) -> str | None:
    """The call of ``name`` on source ``line`` as written (``srand((unsigned)time(NULL))``), or None
    when it does not close on that line."""
    found = re.search(rf"(?:\bstd::)?\b{name}\s*\(", line)
    if found is None:
        return None
    depth = 0
    for i in range(found.end() - 1, len(line)):
        depth += {"(": 1, ")": -1}.get(line[i], 0)
        if depth == 0:
            return line[found.start():i + 1]
    return None
