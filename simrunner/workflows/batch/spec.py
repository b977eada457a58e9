"""What a batch runs: track references, seeds, the parameter grid and the list of jobs.

Everything here is plain data, picklable, and built in the parent process before any worker
starts, so bad input is one line before any run (:class:`BatchError`). Job order (= the
``run`` column): for each track (in the order given, folders and globs sorted), for each
parameter combination (``--param`` options in the order given, values in the order given),
for each seed.

Value lists (``--param NAME=V1,V2,...``): each item is a value (``1.5``, ``3``, ``left``:
:func:`simrunner.run.params.parse_value`) or a range ``START:STOP:STEP`` (inclusive of STOP
when it lands on it; decimal arithmetic, so ``1.0:2.0:0.5`` is exactly 1.0, 1.5, 2.0; all-int
ranges give ints).
"""
from __future__ import annotations

import glob
import itertools
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from pathlib import Path

from simrunner.errors import SimError
from simrunner.run.params import ParamValue, check_name, parse_value

RANDOM_PREFIX = "random:"
MAX_RANGE_VALUES = 10_000
TRACK_FOLDER_MARKERS = ("track.json", "world.sdf", "model.config")
LAYOUT_SUFFIXES = (".txt",)
WORLD_SUFFIXES = (".sdf", ".world")


class BatchError(SimError):
    """Bad batch input: a track that does not exist, a bad value list, a name clash."""


@dataclass(frozen=True)
class TrackRef:
    """One track of a batch: ``label`` (the ``track`` column) and either a ``path`` (layout,
    trackgen folder, world file or model folder) or a ``random_seed`` (``random:N`` gives
    seeds 0..N-1 of :func:`trackgen.random.random_layout`)."""

    label: str
    path: str | None = None
    random_seed: int | None = None


@dataclass(frozen=True)
class Job:
    """One run: its index (``run``), track, seed (camera noise) and parameters."""

    index: int
    track: TrackRef
    seed: int
    params: tuple[tuple[str, ParamValue], ...] = ()


@dataclass(frozen=True)
class BatchConfig:
    """What every run of a batch shares (sent once to each worker).

    ``controller``: absolute path of the controller file; ``program``: the C/C++ program built
    from it (and the batch's other sources, kit, ``--isr``) once for every run, or None (Python).
    ``car``: car TOML path or None.
    ``laps``, ``time_limit_s``, ``dt_s``, ``wall_limit_s``, ``off_track_wheels``, ``event``,
    ``mcu_time``, ``mcu_scale``: as for ``simrunner drive`` (``time_limit_s`` None: each run
    gets drive's default for its track, laps and event).
    """

    controller: str
    car: str | None = None
    program: object | None = None  # a simrunner.run.native.NativeProgram
    laps: int = 1
    time_limit_s: float | None = None
    dt_s: float = 0.002
    wall_limit_s: float = 10.0
    param_names: tuple[str, ...] = field(default_factory=tuple)
    off_track_wheels: int | None = None
    event: str | None = None
    mcu_time: str | float | None = None
    mcu_scale: float = 1.0


def _is_track_folder(path: Path) -> bool:
    return any((path / m).exists() for m in TRACK_FOLDER_MARKERS) or any(
        p.suffix in WORLD_SUFFIXES for p in path.iterdir() if p.is_file())


def _expand_folder(path: Path) -> list[Path]:
    if _is_track_folder(path):
        return [path]
    out = [p for p in sorted(path.iterdir())
           if (p.is_file() and p.suffix.lower() in LAYOUT_SUFFIXES + WORLD_SUFFIXES)
           or (p.is_dir() and _is_track_folder(p))]
    if not out:
        raise BatchError(f"{path}: no tracks in this folder (expected layout .txt files, world "
                         "files or track folders)")
    return out


def _random_count(item: str) -> int:
    text = item[len(RANDOM_PREFIX):]
    if not text.isdigit() or not 1 <= int(text) <= 100_000:
        raise BatchError(f"--tracks {item!r}: expected random:N with 1 <= N <= 100000")
    return int(text)


def resolve_tracks(items: list[str] | tuple[str, ...]) -> list[TrackRef]:
    """``--tracks`` values (each may hold several, comma-separated) -> track references."""
    refs: list[TrackRef] = []
    for item in (part.strip() for value in items for part in value.split(",")):
        if not item:
            continue
        if item.startswith(RANDOM_PREFIX):
            refs += [TrackRef(f"random:{s}", random_seed=s) for s in range(_random_count(item))]
            continue
        if item == "default" and not Path(item).exists():  # the bundled track (drive's default)
            from simrunner.run.runner import default_track

            refs.append(TrackRef("default", path=str(default_track())))
            continue
        if any(ch in item for ch in "*?["):
            matches = [Path(m) for m in sorted(glob.glob(item, recursive=True))]
            if not matches:
                raise BatchError(f"--tracks {item!r}: the pattern matches no file")
        else:
            matches = [Path(item)]
            if not matches[0].exists():
                raise BatchError(f"--tracks {item!r}: no such file or folder")
        for path in matches:
            paths = _expand_folder(path) if path.is_dir() else [path]
            for p in paths:
                if p.is_file() and p.suffix.lower() not in LAYOUT_SUFFIXES + WORLD_SUFFIXES:
                    raise BatchError(f"--tracks {str(p)!r}: not a track (expected a layout .txt, "
                                     "a world .sdf/.world or a track folder)")
                refs.append(TrackRef(str(p), path=str(p.resolve())))
    labels = [r.label for r in refs]
    dup = next((lab for i, lab in enumerate(labels) if lab in labels[:i]), None)
    if dup is not None:
        raise BatchError(f"--tracks: {dup!r} given twice")
    if not refs:
        raise BatchError("--tracks: no track given")
    return refs


def _decimal(text: str, where: str) -> Decimal:
    try:
        d = Decimal(text.strip())
    except InvalidOperation:
        raise BatchError(f"{where}: {text!r} is not a number (a range is START:STOP:STEP)") from None
    if not d.is_finite():
        raise BatchError(f"{where}: {text!r} is not a finite number")
    return d


def parse_values(text: str, where: str = "--param") -> list[ParamValue]:
    """``"1.5,2,left"`` / ``"1.0:2.0:0.5"`` / mixed -> the values, in order."""
    out: list[ParamValue] = []
    for item in text.split(","):
        if item.count(":") == 2 and all(not isinstance(parse_value(p), str) for p in item.split(":")):
            start_t, stop_t, step_t = item.split(":")
            start, stop, step = (_decimal(t, where) for t in (start_t, stop_t, step_t))
            if step <= 0 or stop < start:
                raise BatchError(f"{where}: range {item!r}: expected START <= STOP and STEP > 0")
            count = int((stop - start) / step) + 1
            if count > MAX_RANGE_VALUES:
                raise BatchError(f"{where}: range {item!r} has {count} values (at most "
                                 f"{MAX_RANGE_VALUES})")
            ints = all(isinstance(parse_value(t), int) for t in (start_t, stop_t, step_t))
            out += [int(start + i * step) if ints else float(start + i * step) for i in range(count)]
        elif item.count(":") == 1 and all(not isinstance(parse_value(p), str) for p in item.split(":")):
            raise BatchError(f"{where}: {item.strip()!r}: a range needs its step, START:STOP:STEP "
                             f"(e.g. {item.strip()}:0.5)")
        elif item.strip() == "":
            raise BatchError(f"{where}: empty value in {text!r}")
        else:
            out.append(parse_value(item.strip()))
    return out


def parse_grid(items: list[str] | tuple[str, ...], reserved: tuple[str, ...] = ()) -> dict[str, list[ParamValue]]:
    """``--param NAME=V1,V2`` options -> ``{name: values}`` in the order given."""
    grid: dict[str, list[ParamValue]] = {}
    for item in items:
        name, sep, values = item.partition("=")
        name = name.strip()
        if not sep:
            raise BatchError(f"--param {item!r}: expected NAME=V1,V2,... or NAME=START:STOP:STEP")
        check_name(name)
        if name in grid:
            raise BatchError(f"--param {name} given twice")
        if name in reserved:
            raise BatchError(f"--param {name}: the name of a results column; choose another name")
        grid[name] = parse_values(values, f"--param {name}")
    return grid


def parse_seeds(text: str | int) -> list[int]:
    """``--seeds N`` (seeds 0..N-1) or ``A:B`` (seeds A..B-1)."""
    t = str(text).strip()
    a, sep, b = t.partition(":")
    try:
        lo, hi = (int(a), int(b)) if sep else (0, int(a))
    except ValueError:
        raise BatchError(f"--seeds {t!r}: expected N (seeds 0..N-1) or A:B (seeds A..B-1)") from None
    if lo < 0 or hi <= lo or hi - lo > 100_000:
        raise BatchError(f"--seeds {t!r}: expected N >= 1 (or 0 <= A < B), at most 100000 seeds")
    return list(range(lo, hi))


def make_jobs(tracks: list[TrackRef], seeds: list[int], grid: dict[str, list[ParamValue]]) -> list[Job]:
    """Every (track, parameter combination, seed), in the module docstring's order."""
    names = list(grid)
    combos = list(itertools.product(*(grid[n] for n in names))) if names else [()]
    jobs: list[Job] = []
    for track in tracks:
        for combo in combos:
            for seed in seeds:
                jobs.append(Job(len(jobs), track, seed, tuple(zip(names, combo))))
    return jobs
