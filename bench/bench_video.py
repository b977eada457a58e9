"""The debug video's cost (issue 50): ``simrunner drive examples/line_follower.py --video``.

The whole process, as a student runs it: ``simrunner drive examples/line_follower.py --video
TMP/run.mp4 --summary TMP/run.json`` (the default track, one lap) in a fresh subprocess, the
best of ``REPEAT`` after one untimed run (the OS file cache warm). Columns: the process's wall
time and its real-time factor (simulated seconds / wall seconds; target >= 8x with the video),
its CPU seconds (user + system: what a busy machine inflates less than wall time), the run
loop's own real-time factor from ``--summary``, and the video's frames and size.

Rows: without ``--video`` (for scale), with it on the machine's cores, and with it on one core
(the process pinned to CPU 0: the video's threads cannot run beside the simulation). The target
(issue 50: ">= 8x real time ... one core") is the one-core row's; on two cores the encoding runs
beside the simulation (wall time = CPU time on the ``--video`` row means another process had the
second core). The machine is shared: compare runs made under the same load, and look at the CPU
seconds.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
REPEAT = 7  # (the best of more runs: the machine is shared and its speed varies from run to run)
TARGET_RTF = 8.0
_DRIVE = "import sys; from simrunner.cli import main; sys.exit(main())"


def _env(pycache: str) -> dict:
    """The process's environment as on a student's machine: Python caches the compiled modules
    (``PYTHONDONTWRITEBYTECODE`` unset; the cache kept in ``pycache``, not in the checkout), so a
    start-up after the first does not compile ~80 modules again (~0.1 s)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = pycache
    return env


_PYCACHE = tempfile.mkdtemp(prefix="bench-video-pycache-")


def _one(args: list[str], one_core: bool) -> tuple[float, float]:
    """Wall and CPU seconds of one ``simrunner`` process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", _DRIVE, *args], cwd=REPO, check=True, env=_env(_PYCACHE),
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   preexec_fn=(lambda: os.sched_setaffinity(0, {0})) if one_core else None)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def measure(video: bool, one_core: bool = False, repeat: int = REPEAT) -> dict:
    """The best of ``repeat`` drives (after one untimed): wall, CPU, RTFs, video frames/size."""
    with tempfile.TemporaryDirectory() as tmp:
        summary = Path(tmp) / "run.json"
        args = ["drive", "examples/line_follower.py", "--summary", str(summary)]
        if video:
            args += ["--video", str(Path(tmp) / "run.mp4")]
        _one(args, one_core)
        runs = [_one(args, one_core) for _ in range(repeat)]
        s = json.loads(summary.read_text())
        out = dict(wall_s=min(w for w, _ in runs), cpu_s=min(c for _, c in runs),
                   sim_s=float(s["sim_time_s"]), loop_rtf=float(s["real_time_factor"]), frames=None, mb=None)
        if video:
            import cv2

            cap = cv2.VideoCapture(str(Path(tmp) / "run.mp4"))
            out["frames"] = f"{int(cap.get(cv2.CAP_PROP_FRAME_COUNT))} @ {cap.get(cv2.CAP_PROP_FPS):g} fps"
            cap.release()
            out["mb"] = (Path(tmp) / "run.mp4").stat().st_size / 1e6
    out["rtf"] = out["sim_s"] / out["wall_s"]
    return out


def main() -> None:
    rows = [("no video", measure(False)), ("--video", measure(True)),
            ("--video, one core", measure(True, one_core=True))]
    print(f"simrunner drive examples/line_follower.py (default track, one lap), whole process, "
          f"best of {REPEAT} (target with --video on one core: >= {TARGET_RTF:g}x real time)")
    print("| run | wall s | real-time factor | CPU s | run loop RTF | video |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, r in rows:
        video = "" if r["frames"] is None else f"{r['frames']}, {r['mb']:.1f} MB"
        print(f"| {name} | {r['wall_s']:.2f} | {r['rtf']:.1f}x | {r['cpu_s']:.2f} | "
              f"{r['loop_rtf']:.1f}x | {video} |")
    from bench.record import save

    save("video", {"repeat": REPEAT, "target_rtf": TARGET_RTF, "runs": [
        {"run": name, "wall_s": round(r["wall_s"], 3), "rtf": round(r["rtf"], 2), "cpu_s": round(r["cpu_s"], 3),
         "loop_rtf": round(r["loop_rtf"], 2), "frames": r["frames"],
         "mb": None if r["mb"] is None else round(r["mb"], 2)} for name, r in rows]})


if __name__ == "__main__":
    main()
