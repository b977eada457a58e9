"""Compiling C/C++ controllers (and the host program that runs them), cached by content.

:func:`build_program` turns ``.c``/``.cpp`` sources (plus include directories and defines)
into a shared library with debug info, or takes a prebuilt ``.so`` as it is: a
:class:`NativeProgram`. The build goes to the cache folder (:func:`cache_dir`), keyed by
the compiler, the flags, the working directory and the sources' paths and contents; the
headers a build read (the compiler's ``-MMD`` list) are checked by content on every lookup,
so editing an included header rebuilds. Builds are written to a temporary name and renamed
into place (two runs building at once both succeed).

Errors are :class:`~simrunner.errors.ControllerFileError` (bad input): a missing source, no
compiler (one line naming what to install), or the compiler's own ``file:line:`` messages.
Warnings are kept in ``NativeProgram.warnings`` (also for a cached build) for the caller to
show.
"""
from __future__ import annotations

import difflib
import hashlib
import json
import os
import re
import subprocess
import dataclasses
from dataclasses import dataclass
from pathlib import Path

from simrunner.errors import ControllerFileError
from simrunner.run.delayloops import DelayLoop, delay_loops
from simrunner.run.hostclock import ClockRead, native_clock_reads

NATIVE_DIR = Path(__file__).resolve().parent
INCLUDE_DIR = NATIVE_DIR / "include"
HOST_SOURCE = NATIVE_DIR / "host" / "spinner_host.c"
#: linked into every program built (its __wrap_pthread_create: WRAPPED)
THREAD_START_SOURCE = NATIVE_DIR / "host" / "thread_start.c"
KITS_DIR = NATIVE_DIR / "kits"
#: Kit libraries a firmware builds against (``--kit NAME``): NAME -> its sources beside its include/
#: (in kits/NAME, a ``-`` spelt ``_``). tfc-mbed: the FRDM-TFC library's mbed flavour (C++).
KITS = {"tfc": ("tfc.c", "timers.c"), "s32k144": ("s32k144.c", "gpt.c", "adc.c"),
        "tfc-mbed": ("tfc_mbed.cpp", "sensors.cpp", "interrupt_in.cpp")}
#: A kit's own driver sources in a team's project, which the kit library replaces (passing one is
#: an error naming it rather than the linker's "multiple definition").
KIT_REPLACES = {"s32k144": ("servo.c", "hbridge.c", "esc.c", "linear_camera.c", "display.c",
                            "main_functions.c", "pixy2.c", "receiver.c"),
                # the FRDM-TFC library's sources (Sources/TFC/ of the CodeWarrior/KDS projects)
                "tfc": ("TFC.c", "TFC_ADC.c", "TFC_ARM_SysTick.c", "TFC_BoardSupport.c",
                        "TFC_CrystalClock.c", "TFC_LineScanCamera.c", "TFC_Motor.c", "TFC_Queue.c",
                        "TFC_Servo.c", "TFC_Terminal.c", "TFC_UART.c", "TFC_arm_cm0.c"),
                # the mbed library's source (FRDM-TFC/TFC.cpp of an mbed program)
                "tfc-mbed": ("TFC.cpp",)}
#: The MCU's register names a kit's firmware may write directly (the KL25Z's MKL25Z4.h
#: peripherals, NXP KL25 Sub-Family Reference Manual KL25P80M48SF0RM): not emulated, so a compile
#: error naming one gets a line saying so.
KIT_REGISTERS = {"tfc": re.compile(r"[‘'`]((?:GPIO|FGPIO|PORT)[A-E]_\w+|(?:TPM[0-2]|ADC0|PIT|SIM|UART[0-2]|"
                                   r"I2C[01]|SPI[01]|DMA|DMAMUX0|MCG|OSC0|LPTMR0|SysTick|NVIC|"
                                   r"SCB|RTC|TSI0|DAC0|CMP0|USB0|SMC|PMC|RCM|LLWU)_\w+)[’'`] undeclared"),
                 # C++: the registers as mbed's MKL25Z4.h structs (PTE->PSOR) and mbed's drivers that
                 # the tfc-mbed kit's mbed.h leaves out
                 "tfc-mbed": re.compile(r"[‘'`]((?:PT[A-E]|FPT[A-E]|PORT[A-E]|TPM[0-2]|ADC0|PIT|SIM|UART[0-2]|"
                                        r"I2C[01]|SPI[01]|DMA0|DMAMUX0|MCG|LPTMR0|SysTick|SCB|RTC|TSI0|DAC0|"
                                        r"USB0|SMC|PMC)(?:_\w+)?|I2C|SPI|SPISlave|I2CSlave|CAN|PwmIn|"
                                        r"DigitalInOut|PortIn|PortOut|BusInOut|LowPowerTicker|Thread|ThisThread|"
                                        r"Mutex|Semaphore|EventQueue|Queue|Mail|rtos|USBSerial|NVIC_\w+)[’'`] "
                                        r"(?:undeclared|was not declared|does not name a type)"),
                 # the RTD's calls the s32k144 kit does not declare (docs/firmware.md: the rest of the RTD)
                 "s32k144": re.compile(r"(?:implicit declaration of function |[‘'`])[‘'`]?((?:Mcu|Mcl|Port|Platform|"
                                       r"Adc|Icu|I2c|Uart|Lpuart_Uart_Ip|Spi|Can|Wdg|Pwm|Dio|Gpt|OsIf|Det)_\w+)[’'`]"
                                       r"(?: \[-Werror=implicit-function-declaration\]| was not declared)")}
C_SUFFIXES = (".c",)
MAX_ISRS = 32  # interrupt handlers a program may have (MAX_ISRS in host/spinner_host.c)
CXX_SUFFIXES = (".cpp", ".cc", ".cxx", ".C")
LIB_SUFFIXES = (".so",)
NATIVE_SUFFIXES = C_SUFFIXES + CXX_SUFFIXES + LIB_SUFFIXES
# debug info for file:line in fault reports; -Og keeps lines exact and the code quick. DWARF 4:
# binutils' addr2line (2.40, Debian 12) reads GCC 12's DWARF 5 line table's file 1 as the source
# file itself, so a fault in a function out of a header (a kit's, or the program's own, not
# inlined) was named at the header's line in the .c/.cpp file; the code is the same either way.
COMMON_FLAGS = ("-g", "-gdwarf-4", "-Og", "-fno-omit-frame-pointer", "-fPIC", "-Wall")
C_FLAGS = ("-std=gnu11",)
#: The host's (host/spinner_host.c, both builds). No sibling calls: each API function the program
#: calls keeps its frame, so a report names it (a Spinner call from another thread than main()'s).
HOST_FLAGS = ("-O2", "-g", "-fno-optimize-sibling-calls")
CXX_FLAGS = ("-std=gnu++17",)
# GCC makes the statics of inline functions and templates process-wide (STB_GNU_UNIQUE): a
# library holding one can never be unloaded, and every later run of it would share them.
# Runs in the simulator's process start from fresh globals, so they are made ordinary.
CXX_FRESH_FLAGS = ("-fno-gnu-unique",)
# the sleeps wait in simulated time, an exit ends the program, not the simulator, a forked
# process cannot drive the car, and a thread the program starts (pthread_create, std::thread's
# start in libstdc++) gets an alternate signal stack, so its stack overflow is reported at its line:
# the controller's calls go to __wrap_NAME (host/spinner_host.c, both builds; __wrap_pthread_create
# is THREAD_START_SOURCE's, linked into the program)
STD_THREAD_START = "_ZNSt6thread15_M_start_threadESt10unique_ptrINS_6_StateESt14default_deleteIS1_EEPFvvE"
WRAPPED = ("usleep", "sleep", "nanosleep", "clock_nanosleep", "exit", "_exit", "_Exit", "quick_exit",
           "atexit", "__cxa_atexit", "fork", "pthread_create", STD_THREAD_START)
# -Bsymbolic: the program's calls of its own functions (and uses of its own globals) reach its own
# definitions, as in the firmware on the MCU. Without it a shared library's references go first to
# the process's global scope, where libc is: a program's own `step()` or `index()` ran libc's
# (regex step(3), a SIGSEGV), a global `int daylight` was libc's variable.
LINK_FLAGS = ("-Wl,--wrap=" + ",--wrap=".join(WRAPPED), "-Wl,-Bsymbolic")
INSTALL_HINT = "install a C compiler, e.g. `sudo apt-get install build-essential` (Debian/Ubuntu)"


@dataclass(frozen=True)
class NativeProgram:
    """A controller ready to run: ``library`` (a shared library defining ``main``), the
    ``sources`` it was built from (empty for a prebuilt library), the compiler's
    ``warnings`` text ('' if none), whether it came from the cache, ``isolate``: run it
    in a child process rather than in the simulator's (controller.NativeController), and
    ``isrs``: its functions the simulator calls as timer interrupts, ``(name, period_s)`` each
    (``simrunner drive --isr NAME@HZ``; :func:`with_isrs`); ``kit``: the ``--kit`` it was built
    against (None: none), which names its kit's calls in the run's messages; ``clock_reads``: where
    its own sources read the computer's clock or seed from it (:mod:`simrunner.run.hostclock`;
    found at the build, kept in the cache with it); ``delay_loops``: its own empty counting loops,
    which delay no simulated time (:mod:`simrunner.run.delayloops`; found and kept likewise)."""

    library: Path
    sources: tuple[Path, ...]
    warnings: str = ""
    cached: bool = False
    isolate: bool = False
    isrs: tuple[tuple[str, float], ...] = ()
    kit: str | None = None
    clock_reads: tuple[ClockRead, ...] = ()
    delay_loops: tuple[DelayLoop, ...] = ()

    @property
    def name(self) -> str:
        return (self.sources[0] if self.sources else self.library).stem


def exported_functions(library: str | Path) -> set[str] | None:
    """The function names ``library`` exports (``nm -D --defined-only``), or None where ``nm``
    (binutils) is missing or fails."""
    try:
        out = subprocess.run(["nm", "-D", "--defined-only", str(library)], capture_output=True,
                             text=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    return {parts[2] for parts in (line.split() for line in out.stdout.splitlines())
            if len(parts) == 3 and parts[1] in "TtWi"}


def misspelt_function(program: NativeProgram, message: str) -> str:
    """``message`` (a kit's "... defines no NAME (or OTHER) ..." or "notification NAME ... is not
    a function of the program") with what ``program`` defines that is spelt nearly so after the
    names: a handler the kit never calls because of a typo."""
    found = re.search(r"(?:defines no|notification) (\w+)(?: \(or (\w+)\))?(?=.* (?:is not a function of the "
                      r"program|handler would take it))", message)
    names = exported_functions(program.library) if found else None
    if not names:
        return message
    wanted = [w for w in found.groups() if w]
    end = found.end()
    # the name defined in C++ without extern "C": mangled (Itanium C++ ABI, _Z<length><name>...), it
    # is not the C name the kit (as the board's C start-up file or generated configuration) calls
    mangled = [w for w in wanted if any(n.startswith(f"_Z{len(w)}{w}") for n in names)]
    if mangled:
        return f'{message[:end]} (it defines {mangled[0]} with C++ linkage: declare it extern "C"){message[end:]}'
    close = [c for w in wanted for c in difflib.get_close_matches(w, sorted(names), n=1, cutoff=0.75)]
    if not close:
        return message
    return f"{message[:end]} (it defines {close[0]}: misspelt?){message[end:]}"


def _includes_mbed(source: Path) -> bool:
    """``source`` includes mbed.h."""
    try:
        text = source.read_text(errors="replace")
    except OSError:
        return False  # the compiler says what is wrong with it
    return re.search(r'^\s*#\s*include\s*[<"]mbed\.h[>"]', text, re.M) is not None


def with_isrs(program: NativeProgram, isrs: list[tuple[str, float]]) -> NativeProgram:
    """``program`` whose functions ``isrs`` (``(name, period_s)``) are called as timer interrupts;
    a ControllerFileError when it defines no such function."""
    if not isrs:
        return program
    if len(isrs) > MAX_ISRS:
        raise ControllerFileError(f"--isr: {len(isrs)} handlers, at most {MAX_ISRS} (spinner_host.c's table)")
    names = exported_functions(program.library)
    for name, _ in isrs:
        if names is not None and name not in names:
            where = ", ".join(map(str, program.sources)) or str(program.library)
            raise ControllerFileError(f"--isr {name}: {where} defines no function {name} (expected "
                                      f"void {name}(void), not static)")
    return dataclasses.replace(program, isrs=tuple(isrs))


def build_firmware(sources: list[str | Path], *, include_dirs=(), defines=(), kit: str | None = None,
                   isrs=()) -> NativeProgram:
    """The program of C/C++ ``sources`` as ``drive``, ``check`` and ``batch`` take it: built
    (:func:`build_program`) and its ``isrs`` (``(name, period_s)``) set (:func:`with_isrs`); a
    ControllerFileError when a source is not C/C++ or the build fails."""
    bad = [s for s in sources if not is_native(s)]
    if bad and len(sources) == 1 and not (include_dirs or defines or kit or isrs):
        raise ControllerFileError(f"{bad[0]}: expected a Python controller (.py) or a C/C++ one (.c, .cpp "
                                  f"sources or one .so)")
    if bad:
        raise ControllerFileError(f"{bad[0]}: several files, -I, -D, --kit and --isr are for C/C++ "
                                  f"controllers (.c, .cpp sources or one .so)")
    program = build_program(list(sources), include_dirs=list(include_dirs), defines=list(defines), kit=kit)
    return with_isrs(program, list(isrs))


def is_native(path: str | Path) -> bool:
    """True for a C/C++ source or a shared library (what ``simrunner drive`` compiles/loads)."""
    return Path(path).suffix in NATIVE_SUFFIXES


def cflags() -> str:
    """The compiler flags a hand-made build of a controller needs: ``-I<include dir>``."""
    return f"-I{INCLUDE_DIR}"


def cache_dir() -> Path:
    """``$SIMRUNNER_CACHE_DIR``, else ``$XDG_CACHE_HOME/nxpcup-sim``, else
    ``~/.cache/nxpcup-sim``; C builds go to its ``native/`` folder."""
    root = os.environ.get("SIMRUNNER_CACHE_DIR")
    if not root:
        root = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"),
                            "nxpcup-sim")
    return Path(root) / "native"


def find_compiler(cxx: bool) -> str:
    """The compiler command (``$CXX``/``$CC``, else c++/g++/clang++ or cc/gcc/clang)."""
    import shutil  # here and below: not imported on the cached path's start-up (~10 ms)

    env = os.environ.get("CXX" if cxx else "CC")
    names = [env] if env else (["c++", "g++", "clang++"] if cxx else ["cc", "gcc", "clang"])
    for name in names:
        found = shutil.which(name)
        if found:
            return found
    kind = "C++" if cxx else "C"
    raise ControllerFileError(f"no {kind} compiler found ({', '.join(names)}): {INSTALL_HINT}")


def _digest(*parts: bytes | str) -> str:
    h = hashlib.sha256()
    for p in parts:
        h.update(p.encode() if isinstance(p, str) else p)
        h.update(b"\0")
    return h.hexdigest()[:32]


def _file_digest(path: str | Path) -> str | None:
    try:
        return _digest(Path(path).read_bytes())
    except OSError:
        return None


def _compiler_id(compiler: str) -> str:
    st = os.stat(compiler)
    return f"{os.path.realpath(compiler)}:{st.st_size}:{st.st_mtime_ns}"


def _accepts(compiler: str, flags: tuple[str, ...]) -> bool:
    """Whether the C++ ``compiler`` takes ``flags`` (GCC's own; clang has no such statics).
    Asked once per compiler and flags; the answer is kept in the cache folder."""
    mark = cache_dir() / f"accepts-{_digest(_compiler_id(compiler), *flags)}"
    for answer in ("yes", "no"):
        if mark.with_suffix("." + answer).exists():
            return answer == "yes"
    try:
        done = subprocess.run([compiler, *flags, "-fsyntax-only", "-x", "c++", os.devnull],
                              capture_output=True)
        ok = done.returncode == 0
    except OSError:
        return False
    try:
        mark.parent.mkdir(parents=True, exist_ok=True)
        mark.with_suffix(".yes" if ok else ".no").touch()
    except OSError:
        pass
    return ok


class BuildWarning(UserWarning):
    """A build is slow (the CLIs print it as ``simrunner: warning: ...``)."""


@dataclass(frozen=True)
class BuildLimits:
    """What one compiler or linker run may take. Controllers compile in about a second here
    (examples/line_follower.c 0.3 s, the TFC firmware with its kit 1.1 s); a generated 9 MB
    source ran 340 s at 3.5 GB before these limits.

    ``wall_s``: wall time (s) after which the compiler (its whole process group) is stopped.
    ``memory_mb``: address space (MB, RLIMIT_AS) of each of its processes (the driver, the
    compiler proper, the assembler, the linker). ``slow_after_s``: a build still running
    after this long is reported (:class:`BuildWarning`), then every ``slow_every_s``.
    :meth:`from_env` reads ``SIMRUNNER_BUILD_TIME_S`` and ``SIMRUNNER_BUILD_MEMORY_MB``."""

    wall_s: float = 120.0
    memory_mb: int = 2048
    slow_after_s: float = 5.0
    slow_every_s: float = 30.0

    @classmethod
    def from_env(cls) -> BuildLimits:
        """The defaults, with the limits of the environment variables where set."""
        values = {}
        for var, name, kind in (("SIMRUNNER_BUILD_TIME_S", "wall_s", float),
                                ("SIMRUNNER_BUILD_MEMORY_MB", "memory_mb", int)):
            text = os.environ.get(var)
            if text is None:
                continue
            try:
                value = kind(text)
            except ValueError:
                value = 0
            if not value > 0:
                raise ControllerFileError(f"{var}={text}: expected a number > 0 "
                                          f"({'seconds' if kind is float else 'megabytes'})")
            values[name] = value
        return cls(**values)


_OUT_OF_MEMORY = ("out of memory", "memory exhausted", "cannot allocate memory", "bad_alloc")


def _limit_child(memory_mb: int, cpu_s: float):
    """preexec_fn: the limits, set in the compiler's process before it starts."""
    def limit() -> None:
        import resource

        mem = memory_mb << 20
        resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
        cpu = int(cpu_s) + 1  # a stray grandchild ends by SIGXCPU even if the group kill missed it
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))
    return limit


def _size_text(path: str) -> str:
    try:
        size = os.path.getsize(path)
    except OSError:
        return ""
    return f" ({size / 1e6:.1f} MB)" if size >= 100_000 else ""


def _run(cmd: list[str], what: str, limits: BuildLimits | None = None) -> str:
    """Run the compiler within ``limits`` (:class:`BuildLimits`); its messages (warnings) on
    success; ControllerFileError on failure, one line when a limit stopped it."""
    import signal
    import time
    import warnings

    limits = limits or BuildLimits()
    try:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                errors="replace", start_new_session=True,
                                preexec_fn=_limit_child(limits.memory_mb, limits.wall_s))
    except OSError as exc:
        raise ControllerFileError(f"{what}: cannot run {cmd[0]} ({exc}): {INSTALL_HINT}") from None
    start = time.monotonic()
    report_at = limits.slow_after_s
    try:
        while True:
            elapsed = time.monotonic() - start
            wait = min(report_at, limits.wall_s) - elapsed
            try:
                out, err = proc.communicate(timeout=max(wait, 0.0))
                break
            except subprocess.TimeoutExpired:
                elapsed = time.monotonic() - start
                if elapsed >= limits.wall_s:
                    raise ControllerFileError(
                        f"{what}: compiling stopped at the build time limit of {limits.wall_s:g} s "
                        f"(SIMRUNNER_BUILD_TIME_S=SECONDS sets another)") from None
                if elapsed >= report_at:
                    warnings.warn(f"compiling {what}{_size_text(what)}: {elapsed:.0f} s so far "
                                  f"(stopped at {limits.wall_s:g} s or {limits.memory_mb} MB)",
                                  BuildWarning, stacklevel=2)
                    report_at += limits.slow_every_s
    finally:
        if proc.returncode is None:  # the limit, Ctrl-C: the compiler and its children end
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except OSError:
                pass
            proc.communicate()
    if proc.returncode != 0:
        text = (err + out).rstrip()
        if proc.returncode == -signal.SIGXCPU or "SIGXCPU" in text or "CPU time limit" in text:
            raise ControllerFileError(
                f"{what}: compiling stopped at the build time limit of {limits.wall_s:g} s "
                f"(SIMRUNNER_BUILD_TIME_S=SECONDS sets another)")
        if any(m in text.lower() for m in _OUT_OF_MEMORY):
            raise ControllerFileError(
                f"{what}: compiling needed more than the build memory limit of {limits.memory_mb} MB "
                f"(SIMRUNNER_BUILD_MEMORY_MB=MB sets another)")
        raise ControllerFileError(f"compiling {what} failed:\n{text}")
    return err


def _check_sources(sources: list[str | Path]) -> list[Path]:
    if not sources:
        raise ControllerFileError("no controller source given")
    paths = []
    for s in sources:
        p = Path(s)
        if not p.is_file():
            raise ControllerFileError(f"{p}: no such controller file")
        if p.suffix not in C_SUFFIXES + CXX_SUFFIXES:
            raise ControllerFileError(f"{p}: expected C/C++ sources (.c, .cpp) or one shared "
                                      f"library (.so)")
        paths.append(p)
    return paths


def _cached(entry: Path) -> tuple[Path, str, tuple[ClockRead, ...], tuple[DelayLoop, ...]] | None:
    """(library, warnings, clock reads, delay loops) of a cache entry whose dependencies are unchanged,
    else None."""
    lib, manifest = entry / "controller.so", entry / "manifest.json"
    try:
        data = json.loads(manifest.read_text())
    except (OSError, ValueError):
        return None
    if not lib.is_file():
        return None
    for dep, digest in data.get("deps", {}).items():
        if _file_digest(dep) != digest:
            return None
    return (lib, data.get("warnings", ""), tuple(ClockRead.from_json(r) for r in data.get("clock_reads", ())),
            tuple(DelayLoop.from_json(d) for d in data.get("delay_loops", ())))


def _deps(depfiles: list[Path]) -> dict[str, str]:
    """{path: digest} of every file the compiler read (make-style ``-MMD`` dependency lists)."""
    out: dict[str, str] = {}
    for d in depfiles:
        for path in _dep_paths(d):
            out[path] = _file_digest(path) or ""
    return out


def _dep_paths(depfile: Path) -> list[str]:
    """The absolute paths in a make-style ``-MMD`` dependency list (the source, then its headers)."""
    text = depfile.read_text().replace("\\\n", " ")
    return [os.path.abspath(name) for line in text.splitlines() for name in line.partition(": ")[2].split()]


def _own_files(paths: list[Path], depfiles: list[Path]) -> dict[str, str]:
    """The program's own files - its sources given, not a kit's, and the headers they read that are
    neither the simulator's (its include/, a kit's, the cache's spellings) nor the system's (``-MMD``
    lists none of those): real path -> the name a message shows (a source as given, a header relative
    to the working folder when under it)."""
    cwd = os.getcwd()
    skip = (os.path.realpath(NATIVE_DIR), os.path.realpath(KITS_DIR), os.path.realpath(cache_dir()))
    own: dict[str, str] = {}
    for p, dep in zip(paths, depfiles):
        if KITS_DIR in p.resolve().parents:
            continue
        own[os.path.realpath(p)] = str(p)
        for name in _dep_paths(dep):
            real = os.path.realpath(name)
            if real not in own and not any(real.startswith(s + os.sep) for s in skip):
                rel = os.path.relpath(name, cwd)
                own[real] = name if rel.startswith("..") else rel
    return own


def kit_files(kit: str) -> tuple[list[Path], list[Path]]:
    """``(include dirs, sources)`` of kit library ``kit`` (:data:`KITS`): its own include/ and,
    first, a folder of shims for the spellings code written on Windows (whose file names ignore
    case) uses: ``#include "TFC\\TFC.h"`` (a file of that name including ``TFC/TFC.h``),
    ``Derivative.h``, ``Osif.h``, ``std_types.h`` (each header's name with its first letter
    upper case, capitalised, and all lower case)."""
    if kit not in KITS:
        raise ControllerFileError(f"--kit {kit}: expected one of {', '.join(KITS)}")
    root = KITS_DIR / kit.replace("-", "_")
    include = root / "include"
    headers = sorted(p for p in include.rglob("*.h"))
    shims = {}
    names = {h.relative_to(include).as_posix() for h in headers}
    for h in headers:
        rel = h.relative_to(include).as_posix()
        if "/" in rel:
            shims[rel.replace("/", "\\")] = rel
            continue
        for spelling in (rel[:1].upper() + rel[1:], rel.capitalize(), rel.lower()):
            if spelling not in names:
                shims[spelling] = rel
    key = _digest("kit/2", kit, *(f"{h}\0{_file_digest(h)}" for h in headers))
    shim_dir = cache_dir() / "kits" / f"{kit}-{key}"
    if not shim_dir.is_dir():
        import tempfile

        shim_dir.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".kit-", dir=shim_dir.parent))
        for name, target in shims.items():
            (tmp / name).write_text(f'#include "{target}"\n')
        try:
            os.rename(tmp, shim_dir)
        except OSError:  # another build made it meanwhile
            import shutil

            shutil.rmtree(tmp, ignore_errors=True)
    return [shim_dir, include], [root / name for name in KITS[kit]]


def missing_function(program: NativeProgram, error: str) -> str | None:
    """The one line for a built ``program`` that cannot be loaded because ``error`` (the loader's
    words) names an undefined symbol: where the program uses it and why, from the compiler's
    implicit-declaration warning (a typo: its "did you mean") or the first line of the program's
    own sources naming it (declared in a header, defined in no source given); None for any
    other load error."""
    found = re.search(r"undefined symbol: (\S+)", error)
    if found is None:
        return None
    name = _demangled(found.group(1))
    base = re.escape(name.split("(")[0])
    mine = [Path(s) for s in program.sources if KITS_DIR not in Path(s).resolve().parents]
    implicit = re.search(rf"^(.+?):(\d+):\d+: warning: implicit declaration of function [‘'`]{base}[’'`]"
                         rf"(?:; did you mean [‘'`](\w+)[’'`]\?)?", program.warnings, re.M)
    if implicit:
        hint = f" (did you mean {implicit.group(3)}?)" if implicit.group(3) else ""
        return (f"{implicit.group(1)}:{implicit.group(2)}: {name}: no such function in your sources "
                f"or the libraries they build with{hint}")
    where = ", ".join(map(str, mine)) or str(program.library)
    word = re.compile(rf"\b{re.escape(name.split('(')[0].split('::')[-1])}\b")
    for path in mine:
        try:
            lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
        except OSError:
            continue
        for number, line in enumerate(lines, 1):
            if word.search(line):
                where = f"{path}:{number}"
                break
        else:
            continue
        break
    return (f"{where}: {name} is declared but defined in none of the sources given "
            f"({', '.join(p.name for p in mine)}): pass the source file that defines it")


def _demangled(symbol: str) -> str:
    """A C++ ``symbol`` as C++ spells it (``c++filt``), else as it is."""
    if not symbol.startswith("_Z"):
        return symbol
    try:
        out = subprocess.run(["c++filt", symbol], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return symbol
    return out.stdout.strip() or symbol


def _register_hint(exc: ControllerFileError, kit: str | None) -> ControllerFileError:
    """``exc`` (a failed compile) with a last line when it names MCU registers that ``kit``
    does not emulate (:data:`KIT_REGISTERS`)."""
    pattern = KIT_REGISTERS.get(kit or "")
    names = sorted(set(pattern.findall(str(exc)))) if pattern else []
    if not names:
        return exc
    if kit == "s32k144":
        return ControllerFileError(
            f"{exc}\n{', '.join(names)}: of the RTD's calls the simulator's --kit s32k144 has only the sample's drivers' "
            f"and OsIf, Gpt, Adc's software-triggered group calls, Pwm_SetDutyCycle, Dio's channel calls: the others "
            f"are not emulated - DriversInit() stands for the drivers' set-up; leave their calls out of the sources "
            f"you pass (docs/firmware.md, \"The S32K144 kit\")")
    has = ("it has a timer interrupt's only: LPTMR0, the PIT, TPM2, their SIM and MCG bits, the NVIC"
           if kit == "tfc" else "it has no registers")
    taos = sorted(set(re.findall(r"\bTAOS_(?:CLK|SI)_(?:HIGH|LOW)\b", str(exc))))
    camera = (f" - {', '.join(taos)} are the library's camera pins: a program that clocks the camera out itself "
              f"is not emulated; take the image from the library (LineScanImage0 once LineScanImageReady)"
              if taos and kit in ("tfc", "tfc-mbed") else "")
    return ControllerFileError(
        f"{exc}\n{', '.join(names)}: the MCU's registers{' or mbed drivers' if kit == 'tfc-mbed' else ''}, "
        f"not emulated by the simulator's --kit {kit} ({has}): reach the hardware "
        f"through the kit library's functions (docs/firmware.md){camera}")


def _tickers_hint(exc: ControllerFileError, kit: str | None) -> ControllerFileError:
    """``exc`` with a last line when an mbed program uses ``TFC_Ticker`` without defining it: the
    compiler names the kit's function behind the name (``tfc_mbed_tickers``), not the program's
    array, which mbed's FRDM-TFC library does not have (the CodeWarrior library's SysTick counts it)."""
    text = str(exc).replace("\u2018", "'").replace("\u2019", "'")  # (the compiler's quotes, as its locale has them)
    if kit != "tfc-mbed" or "'tfc_mbed_tickers' was not declared" not in text:
        return exc
    return ControllerFileError(
        f"{exc}\nTFC_Ticker: not declared - mbed's FRDM-TFC library has none (the CodeWarrior library's "
        f"SysTick counted it): define it in your program, `volatile uint32_t TFC_Ticker[4];`, and count it "
        f"with a Ticker of yours (examples/firmware/mbed/main.cpp; docs/firmware.md)")


def _kit_headers() -> dict[str, str]:
    """Each kit's headers as an ``#include`` names them (lower case, ``/``) -> the kit."""
    headers = {}
    for kit in KITS:
        include = KITS_DIR / kit.replace("-", "_") / "include"
        for path in include.rglob("*.h"):
            if not path.name.startswith(("sim_", "tfc_mbed_sim")):
                headers.setdefault(path.relative_to(include).as_posix().lower(), kit)
    return headers


def _include_hint(exc: ControllerFileError, kit: str | None, sources: list[Path]) -> ControllerFileError:
    """``exc`` (a failed compile) with a last line when the compiler found no file for an
    ``#include``: a kit's header built without ``--kit``, or a header of the project's own beside
    its sources that no ``-I`` names (the CodeWarrior layout: ``Sources/``, ``Project_Headers/``)."""
    found = re.search(r"fatal error: (\S+): No such file or directory", str(exc))
    if found is None:
        return exc
    name = found.group(1).replace("\\", "/")
    owner = _kit_headers().get(name.lower())
    if owner is not None and owner != kit:  # (built without --kit, or with the other kit)
        line = (f"{name}: a header of the simulator's --kit {owner}{f', not of --kit {kit}' if kit else ''}: "
                f"build with --kit {owner} (docs/firmware.md)")
    else:
        base = Path(name).name.lower()
        kits = KITS_DIR.resolve()  # (the kit's own sources: its folders are not the project's)
        roots = dict.fromkeys(d for s in sources if not Path(s).resolve().is_relative_to(kits)
                              for d in (s.parent, s.parent.parent))
        homes = sorted({path.parent for root in roots for path in _headers_under(root, 3)
                        if path.name.lower() == base and path.parent not in roots})
        if homes:
            line = f"{name} is in {', '.join(map(str, homes[:3]))}: add -I {homes[0]}"
        elif kit == "s32k144":  # an RTD driver's or the register headers, which the kit has not
            line = (f"{name}: not a header of the simulator's --kit s32k144, which provides the sample's driver "
                    f"headers and of the RTD Std_Types.h, Mcal.h, OsIf.h, Gpt.h, Adc.h, Pwm.h, Dio.h: the RTD's other "
                    f"drivers (Mcu, Port, Platform, Icu, I2c, Uart) and the registers (S32K144.h) are not "
                    f"emulated - DriversInit() stands for their set-up; leave their calls out of the sources you "
                    f"pass (docs/firmware.md, \"The S32K144 kit\")")
        else:
            return exc
    err = ControllerFileError(f"{exc}\n{line}")
    err.hint = line  # (what a shortened report of the compiler's words keeps: simrunner batch)
    return err


def _headers_under(root: Path, depth: int):
    """The ``.h`` files at most ``depth`` folders below ``root`` (hidden folders skipped)."""
    try:
        entries = list(root.iterdir())
    except OSError:
        return
    for entry in entries:
        if entry.name.startswith("."):
            continue
        if entry.is_dir() and depth > 0:
            yield from _headers_under(entry, depth - 1)
        elif entry.suffix.lower() in (".h", ".hpp"):
            yield entry


def _spelling_dir(sources: list[str | Path], include_dirs: list[str | Path]) -> list[Path]:
    """A folder of the Windows spellings of the firmware's includes (:mod:`.spellings`), or []
    when every include resolves as written."""
    from simrunner.run.native.spellings import include_shims, write_shims

    shims = include_shims([Path(s) for s in sources if Path(s).suffix not in LIB_SUFFIXES],
                          [Path(d) for d in include_dirs if Path(d).is_dir()])
    if not shims:
        return []
    key = _digest("spellings/1", *sorted(f"{k}\0{v}" for k, v in shims.items()))
    folder = cache_dir() / "spellings" / key
    if not folder.is_dir():
        import shutil
        import tempfile

        folder.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".spell-", dir=folder.parent))
        write_shims(tmp, shims)
        try:
            os.rename(tmp, folder)
        except OSError:  # another build made it meanwhile
            shutil.rmtree(tmp, ignore_errors=True)
    return [folder]


def build_program(sources: list[str | Path], *, include_dirs: list[str | Path] = (),
                  defines: list[str] = (), kit: str | None = None,
                  limits: BuildLimits | None = None) -> NativeProgram:
    """Compile ``sources`` into a cached shared library (or take one prebuilt ``.so``); with
    ``kit``, against that kit library's headers and sources (:func:`kit_files`). Each
    compiler run is held to ``limits`` (default :meth:`BuildLimits.from_env`)."""
    if kit is not None:
        kit_includes, kit_sources = kit_files(kit)
        for s in sources:
            if Path(s).name in KIT_REPLACES.get(kit, ()):
                raise ControllerFileError(f"{s}: the kit's own driver source: --kit {kit} provides "
                                          f"{Path(s).stem}.h's functions on the simulated car; leave it out (functions of "
                                          f"your own in it go in a file of your own)")
            if kit == "tfc-mbed" and Path(s).suffix in C_SUFFIXES and _includes_mbed(Path(s)):
                raise ControllerFileError(f"{s}: includes mbed.h, whose API is C++: name the file "
                                          f"{Path(s).stem}.cpp (as mbed's own tools compile it)")
        # the kit's headers first: a project's own copies of them (Project_Headers/TFC/, with the
        # MCU's registers) are what the kit replaces; then the Windows spellings of its includes
        include_dirs = [*kit_includes, *include_dirs]
        include_dirs.extend(_spelling_dir(sources, include_dirs))
        sources = [*sources, *kit_sources]
    if len(sources) == 1 and Path(sources[0]).suffix in LIB_SUFFIXES:
        lib = Path(sources[0])
        if not lib.is_file():
            raise ControllerFileError(f"{lib}: no such controller file")
        return NativeProgram(lib.resolve(), ())
    paths = _check_sources(list(sources))
    for d in include_dirs:
        if not Path(d).is_dir():
            raise ControllerFileError(f"{d}: no such include directory (-I)")
    cxx = any(p.suffix in CXX_SUFFIXES for p in paths)
    compilers = {False: find_compiler(False) if not all(p.suffix in CXX_SUFFIXES for p in paths) else None,
                 True: find_compiler(True) if cxx else None}
    flags = [*(f"-I{d}" for d in include_dirs), f"-I{INCLUDE_DIR}", *(f"-D{d}" for d in defines)]
    cwd = os.getcwd()
    cxx_flags = CXX_FLAGS + (CXX_FRESH_FLAGS if cxx and _accepts(compilers[True], CXX_FRESH_FLAGS) else ())
    key = _digest("controller/4", cwd, *map(str, flags), *COMMON_FLAGS, *cxx_flags, *LINK_FLAGS,
                  *(_compiler_id(c) for c in compilers.values() if c), _file_digest(THREAD_START_SOURCE),
                  *(f"{p}\0{_file_digest(p)}" for p in paths))
    entry = cache_dir() / key
    hit = _cached(entry)
    if hit is not None:
        return NativeProgram(hit[0], tuple(paths), hit[1], cached=True, kit=kit, clock_reads=hit[2],
                             delay_loops=hit[3])
    import shutil
    import tempfile

    limits = limits or BuildLimits.from_env()
    entry.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".build-", dir=entry.parent))
    try:
        warnings, objects, depfiles = [], [], []
        for i, p in enumerate(paths):
            is_cxx = p.suffix in CXX_SUFFIXES
            obj, dep = tmp / f"{i}.o", tmp / f"{i}.d"
            cmd = [compilers[is_cxx], *COMMON_FLAGS, *(cxx_flags if is_cxx else C_FLAGS), *flags,
                   "-MMD", "-MF", str(dep), "-c", str(p), "-o", str(obj)]
            try:
                warnings.append(_run(cmd, str(p), limits))
            except ControllerFileError as exc:
                raise _include_hint(_register_hint(_tickers_hint(exc, kit), kit), kit, paths) from None
            objects.append(str(obj))
            depfiles.append(dep)
        linker = compilers[True] if cxx else compilers[False]
        objects.append(str(tmp / "thread_start.o"))  # (__wrap_pthread_create: WRAPPED)
        _run([linker, "-x", "c", "-O2", "-g", "-fPIC", "-c", str(THREAD_START_SOURCE), "-o", objects[-1]],
             "the simrunner thread start", limits)
        warnings.append(_run([linker, "-shared", "-g", *LINK_FLAGS, *objects, "-o",
                              str(tmp / "controller.so"), "-lm"], ", ".join(map(str, paths)), limits))
        text = "".join(warnings)
        deps = _deps(depfiles)
        # where the program's own code reads the computer's clock: its objects' calls (not the kit's)
        own = _own_files(paths, depfiles)
        reads = native_clock_reads([Path(o) for o, p in zip(objects, paths) if KITS_DIR not in p.resolve().parents],
                                   own)
        # and where it delays with an empty counting loop (a scan of its own sources' and headers' text)
        loops = delay_loops(own, kit)
        (tmp / "manifest.json").write_text(json.dumps({"deps": deps, "warnings": text,
                                                       "clock_reads": [r.to_json() for r in reads],
                                                       "delay_loops": [d.to_json() for d in loops]}))
        for o in objects:
            os.unlink(o)
        try:
            os.rename(tmp, entry)
        except OSError:  # another run built it meanwhile (or a stale entry is in the way)
            if _cached(entry) is None:
                shutil.rmtree(entry, ignore_errors=True)
                os.rename(tmp, entry)
            else:
                shutil.rmtree(tmp, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return NativeProgram(entry / "controller.so", tuple(paths), text, cached=False, kit=kit, clock_reads=reads,
                         delay_loops=loops)


def _build_host(kind: str, suffix: str, flags: list[str], libs: list[str]) -> Path:
    """Build ``host/spinner_host.c`` once per compiler and source (cached by content)."""
    compiler = find_compiler(False)
    key = _digest(f"{kind}/1", _compiler_id(compiler), HOST_SOURCE.read_bytes(),
                  (INCLUDE_DIR / "spinner.h").read_bytes(), *flags)
    out = cache_dir() / f"{kind}-{key}{suffix}"
    if out.is_file():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}")
    try:
        _run([compiler, *HOST_FLAGS, *flags, f"-I{INCLUDE_DIR}", str(HOST_SOURCE), "-o", str(tmp),
              *libs], "the simrunner host program", BuildLimits.from_env())
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()
    return out


def host_program() -> Path:
    """The host executable: runs a controller in a child process (bridge.py)."""
    return _build_host("spinner_host", "", ["-rdynamic"], ["-ldl", "-lm"])


def inproc_library() -> Path:
    """The in-process host library: runs a controller as a coroutine in this process."""
    return _build_host("spinner_inproc", ".so", ["-shared", "-fPIC", "-DSPINNER_INPROC"],
                       ["-ldl", "-lm", "-lpthread"])
