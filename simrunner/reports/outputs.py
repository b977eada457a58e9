"""Writing a run's outputs: run-log CSV, video, plot and summary JSON (all atomic)."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from simrunner.errors import SimError
from simrunner.telemetry.log import write_log
from vehicle.userfiles import write_atomic


@dataclass(frozen=True)
class Outputs:
    """Where to write a run's outputs (None: not written)."""

    video: str | Path | None = None
    csv: str | Path | None = None
    plot: str | Path | None = None
    summary: str | Path | None = None
    video_fps: float | None = None  # the video's highest frame rate (None: VideoRecorder's default)


NO_VIDEO = "no video: the run ended before its first camera frame"
"""The run's warning when a video was asked for and the run recorded no frame (a C/C++ program's
fault or exit in a constructor as its library loaded into the simulator's process): the CSV is
still written (its header), the video is not."""


def write_outputs(result, outputs: Outputs, video, track, *, csv_stream=None) -> None:
    """Write what a run's ``result`` (a :class:`simrunner.run.result.RunResult`) asks for. Close the video (``video``: the run's VideoRecorder or None) and the CSV
    (``csv_stream``: the run's :class:`~simrunner.telemetry.stream.CsvStream`, else ``result.log``
    is written) and write plot and summary. All are attempted; the first error is raised
    after the others were written. ``result.outputs`` names what was written."""
    errors: list[SimError] = []
    if video is not None:
        try:
            p = video.close()
            if p is not None:  # (named as given: the recorder may hold it absolute)
                result.outputs["video"] = str(p if outputs.video is None else outputs.video)
            else:  # (an .mp4 holds at least one frame: none is written, and the run says so)
                result.warnings.append(NO_VIDEO)
        except SimError as exc:
            errors.append(exc)
    if csv_stream is not None:  # (without outputs.csv: a supervisor's copy, not an output)
        try:
            csv_stream.close()
            if outputs.csv is not None:  # as given (the stream holds it absolute, against a controller's chdir)
                result.outputs["csv"] = str(outputs.csv)
        except SimError as exc:
            errors.append(exc)
    elif outputs.csv is not None:
        try:
            result.outputs["csv"] = str(write_log(result.log, outputs.csv))
        except SimError as exc:
            errors.append(exc)
    if outputs.plot is not None:
        try:
            from simrunner.reports.plot import plot_run

            result.outputs["plot"] = str(plot_run(result.log, track, outputs.plot, title=plot_title(result),
                                                  lap_times_s=result.lap_times_s))
        except SimError as exc:
            errors.append(exc)
    if outputs.summary is not None:
        path = Path(outputs.summary)
        result.outputs["summary"] = str(path)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_atomic(path, json.dumps(result.summary(), indent=2) + "\n")
        except OSError as exc:
            errors.append(SimError(f"{path}: cannot write summary ({exc.strerror})"))
    if errors:
        raise errors[0]


def plot_title(r) -> str:
    """The plot's title line of a run's result (a :class:`simrunner.run.result.RunResult`)."""
    laps = ", ".join(f"{t:.2f} s" for t in r.lap_times_s) or "none"
    return f"{Path(r.track).name}: {r.outcome}, laps {r.laps_completed}/{r.laps} ({laps})"


_SUFFIXES = {"video": (".mp4",), "plot": (), "summary": (), "csv": ()}
_EXAMPLE = {"video": "run.mp4", "plot": "run.png", "summary": "summary.json", "csv": "run.csv"}
_OPTION = {"video": "--video", "csv": "--csv", "plot": "--plot", "summary": "--summary"}


def check_outputs(outputs: Outputs) -> None:
    """Check every output path before a run (one line, :class:`SimError`, nothing written):
    not an existing folder, not the same file twice, its folder creatable and writable, the
    video an ``.mp4``."""
    seen: dict[Path, str] = {}
    for kind in ("csv", "video", "plot", "summary"):
        value = getattr(outputs, kind)
        if value is None:
            continue
        path = Path(value)
        opt = f"{_OPTION[kind]} {path}"
        if str(value) == "" or path.name in ("", ".", ".."):
            raise SimError(f"{opt}: expected a file path")
        if path.is_dir():
            raise SimError(f"{opt}: is a folder; expected a file path (e.g. {path / _EXAMPLE[kind]})")
        if _SUFFIXES[kind] and path.suffix.lower() not in _SUFFIXES[kind]:
            raise SimError(f"{opt}: expected a {' or '.join(_SUFFIXES[kind])} file")
        key = path.resolve()
        if key in seen:
            raise SimError(f"{opt}: the same file as {seen[key]}")
        seen[key] = opt
        parent = path.parent
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        if not parent.is_dir():
            raise SimError(f"{opt}: {parent} is not a folder")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise SimError(f"{opt}: cannot write in {parent} (permission denied)")
        if path.exists() and not os.access(path, os.W_OK):
            raise SimError(f"{opt}: the file exists and is not writable")
