"""Fuzz the world readers: mutate NXP's two tracks (SDF text and STL bytes) at random and
check that ``trackgen validate`` and ``simrunner drive``'s track loading agree, in bounded
time and memory, without a traceback.

    python -m bench.fuzz_worlds [--seconds 180] [--seed 1] [--tracks DIR] [--keep DIR]

Each sample copies one track, applies 1-3 random mutations (a span of an SDF file deleted,
duplicated or replaced by an SDF fragment or an extreme number; an STL truncated, padded,
bit-flipped, or a coordinate set to an extreme value; its header count changed), then runs
``trackgen.build.validate_path`` and ``simrunner.track.load_track`` in a worker process
(address space limited to ``--memory-gb``, each sample to ``--timeout`` seconds). Findings:
an exception that is not the package's error (a traceback), a timeout or memory error, and a
verdict that differs (one refuses, the other accepts; both refuse with different lines). A
start pose off the road counts as refused for both (validate reports it as a problem).
Findings are printed with the seed and sample number (re-run with the same seed to get the
same mutations) and, with ``--keep``, the mutated world is kept.
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import re
import shutil
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

TRACKS = Path(__file__).resolve().parents[2] / "shared" / "tracks"
FRAGMENTS = [
    "<include><uri>model://nxp_raceway</uri></include>", "<include><uri>model://..</uri></include>",
    "<model name='x'>", "</model>", "<link name='l'>", "</link>", "<pose>1e6 0 0 0 0 0</pose>",
    "<pose relative_to='nowhere'>0 0 0 0 0 0</pose>", "<uri>../../../etc/passwd</uri>",
    "<uri>model://nxp_raceway/../../x.stl</uri>", "<scale>1e9 1 1</scale>", "<scale>0 0 0</scale>",
    "<scale>nan 1 1</scale>", "<mesh><uri>meshes/none.stl</uri></mesh>", "<!DOCTYPE sdf>", "&amp;",
    "<![CDATA[x]]>", "\x00", "\xff", "..", "1e308", "-1e308", "nan", "inf", "9" * 400, "<", ">",
]
NUMBERS = ["0", "-0", "1e6", "-1e6", "1e308", "nan", "inf", "1e-300", "3.5", "-2", "99999999999"]


def _mutate_text(rng: np.random.Generator, text: str) -> str:
    op = rng.integers(5)
    n = len(text)
    i = int(rng.integers(n + 1))
    j = min(n, i + int(rng.integers(1, 200)))
    if op == 0:
        return text[:i] + text[j:]
    if op == 1:
        return text[:j] + text[i:j] + text[j:]
    if op == 2:
        return text[:i] + FRAGMENTS[int(rng.integers(len(FRAGMENTS)))] + text[i:]
    if op == 3:
        nums = list(re.finditer(r"-?\d+\.?\d*(?:e-?\d+)?", text))
        if nums:
            m = nums[int(rng.integers(len(nums)))]
            return text[:m.start()] + NUMBERS[int(rng.integers(len(NUMBERS)))] + text[m.end():]
    return text[:i]


def _mutate_stl(rng: np.random.Generator, data: bytes) -> bytes:
    op = rng.integers(6)
    n = len(data)
    if op == 0:
        return data[: int(rng.integers(n + 1))]
    if op == 1:
        return data + bytes(rng.integers(0, 256, int(rng.integers(1, 200)), dtype=np.uint8))
    if op == 2:
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 20))):
            k = int(rng.integers(n))
            b[k] ^= 1 << int(rng.integers(8))
        return bytes(b)
    if op == 3 and n > 84:  # a coordinate of some triangle to an extreme value
        count = (n - 84) // 50
        k = 84 + 50 * int(rng.integers(max(count, 1))) + 12 + 4 * int(rng.integers(9))
        value = np.float32(rng.choice([1e6, -1e6, 3e38, np.nan, np.inf, 0.0]))
        return data[:k] + value.tobytes() + data[k + 4:]
    if op == 4 and n >= 84:
        count = int(rng.choice([0, 1, 2**31, 2**32 - 1, (n - 84) // 50 + 1]))
        return data[:80] + count.to_bytes(4, "little") + data[84:]
    return bytes(rng.integers(0, 256, int(rng.integers(0, 3000)), dtype=np.uint8))


def mutate(rng: np.random.Generator, folder: Path) -> list[str]:
    """Apply 1-3 mutations to the files of ``folder``; what was done, one line each."""
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix in (".world", ".sdf", ".config", ".stl", ".json"))
    done = []
    for _ in range(int(rng.integers(1, 4))):
        f = files[int(rng.integers(len(files)))]
        if f.suffix == ".stl":
            f.write_bytes(_mutate_stl(rng, f.read_bytes()))
        else:
            f.write_text(_mutate_text(rng, f.read_text(errors="surrogateescape")), errors="surrogateescape")
        done.append(f.relative_to(folder).as_posix())
    return done


def _limit_memory(gb: float) -> None:
    import resource

    limit = int(gb * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def verdicts(folder: str) -> tuple[str, str]:
    """(validate, drive) verdicts: ``ok``, ``refused: LINE`` or ``crash: TRACEBACK``."""
    from simrunner.track import TrackLoadError, load_track
    from trackgen.build import validate_path
    from trackgen.errors import TrackError
    from worlds import WorldError

    try:
        problems = validate_path(folder, sdf_checker=False)
        start = [p for p in problems if p.check == "start" and not p.warning]
        v = f"refused: {start[0].path}: {start[0].message}" if start else "ok"
    except (WorldError, TrackError) as exc:
        v = f"refused: {exc}"
    except BaseException:  # noqa: BLE001 - a finding
        v = "crash: " + traceback.format_exc(limit=6)
    try:
        load_track(folder)
        d = "ok"
    except TrackLoadError as exc:
        d = f"refused: {exc}"
    except BaseException:  # noqa: BLE001 - a finding
        d = "crash: " + traceback.format_exc(limit=6)
    return v, d


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=180.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--tracks", type=Path, default=TRACKS, help="a folder of track folders to mutate")
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--memory-gb", type=float, default=3.0)
    ap.add_argument("--keep", type=Path, default=None, help="keep the worlds of findings here")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    names = sorted(p.name for p in args.tracks.iterdir() if p.is_dir() and not p.name.startswith("."))
    ctx = mp.get_context("spawn")
    pool = ctx.Pool(1, initializer=_limit_memory, initargs=(args.memory_gb,))
    findings = samples = 0
    counts: dict[str, int] = {}
    end = time.monotonic() + args.seconds
    with tempfile.TemporaryDirectory(prefix="fuzz-worlds-") as tmp:
        while time.monotonic() < end:
            samples += 1
            name = names[int(rng.integers(len(names)))]
            folder = Path(tmp) / f"s{samples}" / name
            shutil.copytree(args.tracks / name, folder)
            done = mutate(rng, folder)
            t0 = time.monotonic()
            try:
                v, d = pool.apply_async(verdicts, (str(folder),)).get(args.timeout)
            except mp.TimeoutError:
                v = d = f"crash: timeout after {args.timeout:g} s"
                pool.terminate()
                pool = ctx.Pool(1, initializer=_limit_memory, initargs=(args.memory_gb,))
            except Exception as exc:  # noqa: BLE001 - the worker died (memory)
                v = d = f"crash: worker died ({exc!r})"
                pool.terminate()
                pool = ctx.Pool(1, initializer=_limit_memory, initargs=(args.memory_gb,))
            key = "agree-ok" if v == d == "ok" else "agree-refused" if v == d else "finding"
            if v.startswith("refused") and d.startswith("refused") and v != d:
                key = "finding"  # both refuse, in other words
            if v.startswith("crash") or d.startswith("crash"):
                key = "finding"
            counts[key] = counts.get(key, 0) + 1
            if key == "finding":
                findings += 1
                print(f"FINDING seed {args.seed} sample {samples} ({name}; {', '.join(done)}; "
                      f"{time.monotonic() - t0:.1f} s)\n  validate: {v.strip()}\n  drive:    {d.strip()}")
                if args.keep is not None:
                    shutil.copytree(folder, args.keep / f"s{samples}" / name, dirs_exist_ok=True)
            shutil.rmtree(folder.parent, ignore_errors=True)
    pool.terminate()
    print(f"{samples} samples in {args.seconds:g} s (seed {args.seed}): "
          + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return 1 if findings else 0


if __name__ == "__main__":
    raise SystemExit(main())
