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

import hashlib
import json
import os
import subprocess
from dataclasses import dataclass
from pathlib import Path

from simrunner.errors import ControllerFileError

NATIVE_DIR = Path(__file__).resolve().parent
INCLUDE_DIR = NATIVE_DIR / "include"
HOST_SOURCE = NATIVE_DIR / "host" / "spinner_host.c"
KITS_DIR = NATIVE_DIR / "kits"
#: Kit libraries a firmware builds against (``--kit NAME``): NAME -> its sources beside its include/.
KITS = {"tfc": ("tfc.c",)}
C_SUFFIXES = (".c",)
CXX_SUFFIXES = (".cpp", ".cc", ".cxx", ".C")
LIB_SUFFIXES = (".so",)
NATIVE_SUFFIXES = C_SUFFIXES + CXX_SUFFIXES + LIB_SUFFIXES
# debug info for file:line in fault reports; -Og keeps lines exact and the code quick
COMMON_FLAGS = ("-g", "-Og", "-fno-omit-frame-pointer", "-fPIC", "-Wall")
C_FLAGS = ("-std=gnu11",)
CXX_FLAGS = ("-std=gnu++17",)
# GCC makes the statics of inline functions and templates process-wide (STB_GNU_UNIQUE): a
# library holding one can never be unloaded, and every later run of it would share them.
# Runs in the simulator's process start from fresh globals, so they are made ordinary.
CXX_FRESH_FLAGS = ("-fno-gnu-unique",)
# the sleeps wait in simulated time, an exit ends the program, not the simulator, and a forked
# process cannot drive the car: the controller's calls go to __wrap_NAME (host/spinner_host.c,
# both builds)
WRAPPED = ("usleep", "sleep", "nanosleep", "clock_nanosleep", "exit", "_exit", "_Exit", "quick_exit",
           "atexit", "__cxa_atexit", "fork")
LINK_FLAGS = ("-Wl,--wrap=" + ",--wrap=".join(WRAPPED),)
INSTALL_HINT = "install a C compiler, e.g. `sudo apt-get install build-essential` (Debian/Ubuntu)"


@dataclass(frozen=True)
class NativeProgram:
    """A controller ready to run: ``library`` (a shared library defining ``main``), the
    ``sources`` it was built from (empty for a prebuilt library), the compiler's
    ``warnings`` text ('' if none), whether it came from the cache, and ``isolate``: run it
    in a child process rather than in the simulator's (controller.NativeController)."""

    library: Path
    sources: tuple[Path, ...]
    warnings: str = ""
    cached: bool = False
    isolate: bool = False

    @property
    def name(self) -> str:
        return (self.sources[0] if self.sources else self.library).stem


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


def _run(cmd: list[str], what: str) -> str:
    """Run the compiler; its messages (warnings) on success; ControllerFileError on failure."""
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, errors="replace")
    except OSError as exc:
        raise ControllerFileError(f"{what}: cannot run {cmd[0]} ({exc}): {INSTALL_HINT}") from None
    if proc.returncode != 0:
        out = (proc.stderr + proc.stdout).rstrip()
        raise ControllerFileError(f"compiling {what} failed:\n{out}")
    return proc.stderr


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


def _cached(entry: Path) -> tuple[Path, str] | None:
    """(library, warnings) of a cache entry whose dependencies are unchanged, else None."""
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
    return lib, data.get("warnings", "")


def _deps(depfiles: list[Path]) -> dict[str, str]:
    """{path: digest} of every file the compiler read (make-style ``-MMD`` dependency lists)."""
    out: dict[str, str] = {}
    for d in depfiles:
        text = d.read_text().replace("\\\n", " ")
        for line in text.splitlines():
            _, _, rest = line.partition(": ")
            for name in rest.split():
                path = os.path.abspath(name)
                out[path] = _file_digest(path) or ""
    return out


def kit_files(kit: str) -> tuple[list[Path], list[Path]]:
    """``(include dirs, sources)`` of kit library ``kit`` (:data:`KITS`): its own include/ and,
    first, a folder of shims for the spellings code written on Windows uses
    (``#include "TFC\\TFC.h"``: a file of that name including ``TFC/TFC.h``; ``Derivative.h``)."""
    if kit not in KITS:
        raise ControllerFileError(f"--kit {kit}: expected one of {', '.join(KITS)}")
    root = KITS_DIR / kit
    include = root / "include"
    headers = sorted(p for p in include.rglob("*.h"))
    shims = {}
    for h in headers:
        rel = h.relative_to(include).as_posix()
        if "/" in rel:
            shims[rel.replace("/", "\\")] = rel
        if rel != rel[:1].upper() + rel[1:]:
            shims[rel[:1].upper() + rel[1:]] = rel
    key = _digest("kit/1", kit, *(f"{h}\0{_file_digest(h)}" for h in headers))
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


def build_program(sources: list[str | Path], *, include_dirs: list[str | Path] = (),
                  defines: list[str] = (), kit: str | None = None) -> NativeProgram:
    """Compile ``sources`` into a cached shared library (or take one prebuilt ``.so``); with
    ``kit``, against that kit library's headers and sources (:func:`kit_files`)."""
    if kit is not None:
        kit_includes, kit_sources = kit_files(kit)
        include_dirs = [*include_dirs, *kit_includes]
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
    key = _digest("controller/2", cwd, *map(str, flags), *COMMON_FLAGS, *cxx_flags, *LINK_FLAGS,
                  *(_compiler_id(c) for c in compilers.values() if c),
                  *(f"{p}\0{_file_digest(p)}" for p in paths))
    entry = cache_dir() / key
    hit = _cached(entry)
    if hit is not None:
        return NativeProgram(hit[0], tuple(paths), hit[1], cached=True)
    import shutil
    import tempfile

    entry.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".build-", dir=entry.parent))
    try:
        warnings, objects, depfiles = [], [], []
        for i, p in enumerate(paths):
            is_cxx = p.suffix in CXX_SUFFIXES
            obj, dep = tmp / f"{i}.o", tmp / f"{i}.d"
            cmd = [compilers[is_cxx], *COMMON_FLAGS, *(cxx_flags if is_cxx else C_FLAGS), *flags,
                   "-MMD", "-MF", str(dep), "-c", str(p), "-o", str(obj)]
            warnings.append(_run(cmd, str(p)))
            objects.append(str(obj))
            depfiles.append(dep)
        linker = compilers[True] if cxx else compilers[False]
        warnings.append(_run([linker, "-shared", "-g", *LINK_FLAGS, *objects, "-o",
                              str(tmp / "controller.so"), "-lm"], ", ".join(map(str, paths))))
        text = "".join(warnings)
        deps = _deps(depfiles)
        (tmp / "manifest.json").write_text(json.dumps({"deps": deps, "warnings": text}))
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
    return NativeProgram(entry / "controller.so", tuple(paths), text, cached=False)


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
        _run([compiler, "-O2", "-g", *flags, f"-I{INCLUDE_DIR}", str(HOST_SOURCE), "-o", str(tmp),
              *libs], "the simrunner host program")
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
