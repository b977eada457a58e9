"""Output folders written beside their place and swapped in whole: ``trackgen build``,
``simrunner gap``, ``simrunner calibrate-camera`` (output files: ``vehicle.userfiles.write_atomic``).

* A build writes into ``.NAME.trackgen-PID-XXXXXXXX.tmp`` beside ``NAME`` (same file
  system, so the final step is a rename). The process id in the name lets a later build
  remove the folders of builds that were killed: :func:`clean_stale` removes those whose
  process no longer runs (folders of running builds, and anything not named this way, are
  left alone).
* A new ``NAME`` is renamed into place. An existing one (``--force``) is exchanged with the
  new build in one atomic step (Linux ``renameat2(RENAME_EXCHANGE)``), so ``NAME`` always
  holds a complete build, the old one or the new one; the old one is then removed. Where
  the exchange is not available (another OS, a file system without it) the old folder is
  renamed aside first: ``NAME`` is then missing between two renames (microseconds).
"""
from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import re
import shutil
import tempfile
from pathlib import Path

_TAG = "trackgen"
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def _pattern(out_dir: Path) -> re.Pattern:
    return re.compile(rf"\.{re.escape(out_dir.name)}\.{_TAG}-(\d+)-[^/]*\.(?:tmp|old)\Z")


def make_temp(out_dir: Path, suffix: str = ".tmp") -> Path:
    """A new empty folder beside ``out_dir`` named after it and this process, with the
    permissions a folder made with ``mkdir`` would get (mkdtemp's are 0700: a teammate could
    not read the output swapped in from it)."""
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.{_TAG}-{os.getpid()}-", suffix=suffix,
                                dir=out_dir.parent))
    os.chmod(tmp, 0o777 & ~process_umask())
    return tmp


def process_umask() -> int:
    """This process's file-creation mask: from /proc (Linux 4.7+: no change to the mask, which
    other threads may be using), else by setting it and setting it back."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True  # another user's process (or an impossible pid: keep the folder)
    return True


def clean_stale(out_dir: Path) -> list[Path]:
    """Remove the temporary folders of killed builds of ``out_dir``; return them."""
    pattern = _pattern(out_dir)
    removed = []
    try:
        entries = list(os.scandir(out_dir.parent))
    except OSError:
        return removed
    for entry in entries:
        match = pattern.match(entry.name)
        if match and entry.is_dir(follow_symlinks=False) and not _alive(int(match.group(1))):
            shutil.rmtree(entry.path, ignore_errors=True)
            removed.append(Path(entry.path))
    return removed


def exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (both must exist). ``False`` when the platform or the file
    system cannot; raises ``OSError`` for other failures."""
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


@contextlib.contextmanager
def swapped_in(out_dir: Path):
    """A new temporary sibling of ``out_dir`` (:func:`make_temp`) to write a folder into,
    swapped into ``out_dir`` (:func:`replace_folder`) when the block ends; removed on any error,
    which propagates, so ``out_dir`` is the old folder or the new one, never half of one."""
    tmp = make_temp(out_dir)
    try:
        yield tmp
        replace_folder(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def replace_folder(tmp: Path, out_dir: Path) -> None:
    """Put the finished build ``tmp`` at ``out_dir``, replacing a folder there."""
    if not out_dir.exists():
        os.replace(tmp, out_dir)
        return
    if exchange(tmp, out_dir):
        shutil.rmtree(tmp, ignore_errors=True)  # now the old build
        return
    trash = make_temp(out_dir, ".old")
    os.replace(out_dir, trash / "old")
    os.replace(tmp, out_dir)
    shutil.rmtree(trash, ignore_errors=True)
