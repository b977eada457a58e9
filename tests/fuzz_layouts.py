"""Random-mutation fuzzer for layout files (not collected by pytest; run it by hand).

    python tests/fuzz_layouts.py [SECONDS] [SEED] [STEPS]

Mutates the example layouts (extreme numbers, long tokens, repeats, settings, Unicode
look-alikes, byte damage, shuffled lines) and runs each through ``check_layout`` (chain,
every check, unions and meshes) and, when the layout is valid, track.json and preview.png.
Anything other than a :class:`trackgen.TrackError`, or a case slower than SLOW_S, is
printed with the text that caused it. ``mutate`` is also used by tests/test_hardening.py.
"""
from __future__ import annotations

import sys
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SLOW_S = 5.0
NUMBERS = ["0", "-1", "1e-300", "1e308", "1e12", "1e-12", "nan", "inf", "1" * 5000,
           "0." + "0" * 3000 + "1", "0.0005", "0.001", "100", "100.0001", "180", "180.0001",
           "0.29", "0.2951", "1e4", "99.99", "1e-5", "0.05", "3", "0.6", "1e+2", ".5", "5.",
           "+0.8", "1_0", "١", "0x10"]
WORDS = ["STRAIGHT", "STRAIGHT_SHORT", "CROSSROADS", "TURN_LEFT", "TURN_RIGHT",
         "CHICANE_LEFT", "CHICANE_RIGHT", "START_FINISH", "ſtraight", "straıght", "TURN_LEFT",
         "ＳＴＲＡＩＧＨＴ", "turn_right", "x1000", "x" + "9" * 5000, "x0", "x-1", "x1e3",
         "length=", "radius=", "angle=", "offset=", "mark_length=", "=", "#", "@", "x2",
         "leng\u212ath=1", "MAR\u212a_LENGTH=0.1", " " * 3000, "\u00a0", "\u2028", "é"]
SETTINGS = ["@scale", "@lane_width", "@edge_width", "@thickness", "@arc_tolerance", "@name",
            "@ſcale", "@SCALE"]
KEYS = ["length", "radius", "angle", "offset", "mark_length"]


def mutate(text: str, rng: np.random.Generator, steps: int = 3) -> str:
    """``text`` with 1..steps random edits."""
    lines = text.split("\n")
    for _ in range(int(rng.integers(1, steps + 1))):
        op = int(rng.integers(0, 9))
        i = int(rng.integers(0, max(1, len(lines))))
        if op == 0 and lines:                                     # a parameter, extreme value
            piece = str(rng.choice(WORDS[:8]))
            lines[i] = f"{piece} {rng.choice(KEYS)}={rng.choice(NUMBERS)}"
        elif op == 1:                                             # a setting
            lines.insert(i, f"{rng.choice(SETTINGS)} = {rng.choice(NUMBERS)}")
        elif op == 2 and lines:                                   # a repeat
            lines[i] = lines[i].split("#")[0] + f" x{int(rng.integers(1, 1001))}"
        elif op == 3:                                             # odd words
            lines.insert(i, " ".join(str(w) for w in rng.choice(WORDS, int(rng.integers(1, 4)))))
        elif op == 4 and lines:                                   # delete a line
            lines.pop(i)
        elif op == 5 and lines:                                   # duplicate a line
            lines.insert(i, lines[i])
        elif op == 6 and len(lines) > 1:                          # swap two lines
            j = int(rng.integers(0, len(lines)))
            lines[i], lines[j] = lines[j], lines[i]
        elif op == 7 and lines:                                   # a number in place
            words = lines[i].split()
            if words:
                k = int(rng.integers(0, len(words)))
                key = words[k].partition("=")[0]
                words[k] = f"{key}={rng.choice(NUMBERS)}"
                lines[i] = " ".join(words)
        elif op == 8:                                             # raw characters
            pos = int(rng.integers(0, len(lines[i]) + 1)) if lines else 0
            ch = chr(int(rng.choice([int(rng.integers(32, 127)), int(rng.integers(0x80, 0x3000))])))
            lines[i:i + 1] = [lines[i][:pos] + ch + lines[i][pos:]] if lines else [ch]
    return "\n".join(lines)


def run_case(text: str, tmp: Path) -> None:
    """Parse, check, and for a valid layout export track.json and the preview."""
    from trackgen import TrackError, parse_layout
    from trackgen.build import check_layout
    from trackgen.export import dumps_track_json, track_json
    from trackgen.preview import render_preview

    try:
        checked = check_layout(parse_layout(text, path="fuzz.txt"))
    except TrackError:
        return
    for p in checked.problems:
        assert "\n" not in str(p) and len(str(p)) < 2000, str(p)[:300]
    if checked.ok:
        dumps_track_json(track_json(checked.track, checked.geometry))
        render_preview(checked.track, checked.geometry, tmp / "p.png")


def main(seconds: float = 120.0, seed: int = 0, steps: int = 3) -> int:
    rng = np.random.default_rng(seed)
    bases = [p.read_text() for p in sorted(EXAMPLES.glob("*.txt"))]
    failures = cases = 0
    end = time.monotonic() + seconds
    with tempfile.TemporaryDirectory() as tmp:
        while time.monotonic() < end:
            text = mutate(str(bases[cases % len(bases)]), rng, steps)
            cases += 1
            t0 = time.monotonic()
            try:
                run_case(text, Path(tmp))
            except Exception:  # noqa: BLE001 - the fuzzer reports everything
                failures += 1
                print(f"--- case {cases}: {traceback.format_exc(limit=3)[-800:]}\n{text[:600]!r}",
                      flush=True)
            took = time.monotonic() - t0
            if took > SLOW_S:
                failures += 1
                print(f"--- case {cases}: slow ({took:.1f} s)\n{text[:600]!r}", flush=True)
    print(f"{cases} cases, {failures} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(*(float(a) for a in sys.argv[1:2]), *(int(a) for a in sys.argv[2:4])))
