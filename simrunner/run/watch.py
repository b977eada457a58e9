"""Instant re-runs: :func:`watch_runs` keeps the track and car loaded and runs a controller
file again each time it is saved (``simrunner drive --watch``).

The controller file is polled (its size and modification time, every ``poll_s``); a change
starts a new run with the same track, car and settings: the file is read and compiled
again, so the new run sees the saved code (helper modules of its folder are imported afresh
too, see :mod:`simrunner.run.controller`). A run takes what :func:`~simrunner.run.runner.drive`
takes; its outputs (``csv``, ``plot``, ...) are written again by every run.

A file that does not compile (a syntax error while typing) is not the end: it is reported
like a run (a :class:`WatchEvent` with ``error``) and the next save is awaited.

C and C++ controllers (``make``: builds the program from its sources, compiler errors raise
:class:`~simrunner.errors.ControllerFileError`) are watched the same way: ``watched`` lists
every file whose save starts a new build and run (:func:`native_watched`: the sources and
the headers of their folders and of the include folders); the build cache makes an unchanged
file cost nothing.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from simrunner.errors import ControllerFileError
from simrunner.run.result import RunResult

DEFAULT_POLL_S = 0.02  # stat() of one file: ~2 us; 20 ms keeps the save-to-run delay small


@dataclass(frozen=True)
class WatchEvent:
    """One run of the watched file: its ``result``, or ``error`` (the file could not be
    loaded: one line). ``saved_at``: ``time.perf_counter()`` when the change was seen (the
    first run: when watching started)."""

    number: int
    result: RunResult | None
    error: str | None
    saved_at: float


HEADER_SUFFIXES = (".h", ".hpp", ".hh")


def native_watched(controller, more_sources=(), include_dirs=()) -> tuple[Path, ...]:
    """The files whose saves rebuild a C/C++ controller: its sources and the headers of their
    own folders (``#include "pid.h"`` finds them without ``-I``) and of the ``-I`` folders,
    each once."""
    sources = [Path(controller), *map(Path, more_sources)]
    folders = dict.fromkeys([*(p.parent for p in sources), *map(Path, include_dirs)])
    headers = [p for d in folders for p in sorted(d.glob("*")) if p.suffix in HEADER_SUFFIXES]
    return tuple(dict.fromkeys([*sources, *headers]))


def _signature(paths) -> tuple | None:
    """The (modification time, size) of each of ``paths`` (one path or several); None while
    one cannot be read (a save in progress)."""
    out = []
    for path in (paths if isinstance(paths, (list, tuple)) else [paths]):
        try:
            st = os.stat(path)
        except OSError:
            return None
        out.append((st.st_mtime_ns, st.st_size))
    return tuple(out)


def watch_runs(controller: str | Path, *, track=None, car=None, poll_s: float = DEFAULT_POLL_S,
               max_runs: int | None = None, stop: Callable[[], bool] | None = None,
               make: Callable[[], object] | None = None, watched: tuple = (),
               **drive_options) -> Iterator[WatchEvent]:
    """Run ``controller`` now and after each save; yield a :class:`WatchEvent` per run.

    ``track``, ``car``: as for :func:`~simrunner.run.runner.drive` (loaded once, here).
    ``make``: builds what to drive anew before each run (C/C++: the program), ``watched``: the
    files whose saves start a run (default: ``controller``).
    ``drive_options``: the other keywords of ``drive`` (settings fields, output paths).
    Ends after ``max_runs`` runs, when ``stop()`` returns true (checked between polls), or
    when a run was interrupted (Ctrl-C). Bad track or car input raises before the first run.
    """
    from simrunner.run.runner import drive, resolve_track
    from vehicle.description import CarDescription, load_car

    path = Path(controller)
    files = [Path(p) for p in watched] or [path]
    car_desc = car if isinstance(car, CarDescription) else load_car(car)
    sim_track, _ = resolve_track(track, car_desc)
    number = 0
    seen = _signature(files)
    saved_at = time.perf_counter()
    while True:
        number += 1
        try:
            result = drive(make() if make is not None else path, track=sim_track, car=car_desc,
                           **drive_options)
            event = WatchEvent(number, result, None, saved_at)
        except ControllerFileError as exc:
            event = WatchEvent(number, None, str(exc), saved_at)
        yield event
        if (max_runs is not None and number >= max_runs) or (
                event.result is not None and event.result.outcome == "interrupted"):
            return
        while True:  # wait for the next save
            if stop is not None and stop():
                return
            time.sleep(poll_s)
            now = _signature(files)
            if now is not None and now != seen:
                seen = now
                saved_at = time.perf_counter()
                break
