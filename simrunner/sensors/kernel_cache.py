"""The one on-disk cache left: numba's compiled line kernel, verified before numba reads it.

numba (``cache=True``) keeps an index (``*.nbi``) and machine code (``*.N.nbc``) per
function and trusts them: a truncated data file made every later ``simrunner drive`` fail
with ``UnpicklingError`` (never repaired), and a changed one would run whatever it holds.
So each entry is checked against a manifest of SHA-256 sums written beside it
(``<index>.sha256.json``) by the process that compiled or loaded it:

* :func:`verify` (before the first call in a process): every file of the function's entry
  must match the manifest; otherwise -- truncated, changed, extra, missing, or no manifest
  at all (an entry of unknown origin) -- the entry's files are deleted, so numba compiles
  afresh (~1-2 s, once) and writes a new entry;
* :func:`record` (after the first call): writes the manifest of the files as they now are
  (atomically; nothing when it already matches).

Track loading keeps no cache (layouts are built in memory, worlds read each time). Failing
to delete or write in a read-only cache folder is not an error: numba then uses its own
fallback folder, and an unverifiable entry is simply recompiled.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

from vehicle.userfiles import write_atomic

MANIFEST_SUFFIX = ".sha256.json"


def _entry(dispatcher) -> tuple[Path, list[Path]] | None:
    """The index file of ``dispatcher``'s cache entry and its existing files (index first)."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    index = getattr(cache_file, "_index_path", None)
    if index is None:  # no on-disk cache (cache=False) or another numba layout
        return None
    index = Path(index)
    stem = index.name[: -len(".nbi")] if index.name.endswith(".nbi") else index.stem
    try:
        data = sorted(p for p in index.parent.iterdir()
                      if p.name.startswith(stem + ".") and p.name.endswith(".nbc"))
    except OSError:
        data = []
    return index, ([index] if index.is_file() else []) + data


def _sums(files: list[Path]) -> dict[str, str]:
    out = {}
    for f in files:
        try:
            out[f.name] = hashlib.sha256(f.read_bytes()).hexdigest()
        except OSError:
            out[f.name] = "unreadable"
    return out


def _manifest(index: Path) -> Path:
    return index.with_name(index.name + MANIFEST_SUFFIX)


def verify(dispatcher) -> str:
    """Check ``dispatcher``'s cache entry (module docstring): ``"empty"``, ``"verified"`` or
    ``"dropped"`` (its files deleted, numba recompiles on the first call)."""
    entry = _entry(dispatcher)
    if entry is None or not entry[1]:
        return "empty"
    index, files = entry
    try:
        expected = json.loads(_manifest(index).read_text())
    except (OSError, ValueError):
        expected = None
    if expected == _sums(files):
        return "verified"
    for f in [*files, _manifest(index)]:
        try:
            f.unlink()
        except OSError:
            pass
    return "dropped"


def record(dispatcher) -> None:
    """Write the manifest of ``dispatcher``'s cache entry as it is now (after a call)."""
    entry = _entry(dispatcher)
    if entry is None or not entry[1]:
        return
    index, files = entry
    sums = _sums(files)
    manifest = _manifest(index)
    try:
        if json.loads(manifest.read_text()) == sums:
            return
    except (OSError, ValueError):
        pass
    try:
        write_atomic(manifest, json.dumps(sums, sort_keys=True))
    except OSError:
        pass


def reference_row_kernel():
    """The numba reference kernel (:func:`simrunner.sensors.line_kernel.camera_row`), its
    on-disk entry verified before this process first loads it; call :func:`record` with it
    after its first use so the entry it loaded or wrote is recorded."""
    from simrunner.sensors.line_kernel import camera_row

    if not camera_row.overloads:  # not yet compiled or loaded in this process
        verify(camera_row)
    return camera_row
