"""Writing a run's outputs: run-log CSV, video, plot and summary JSON (all atomic)."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from simrunner.errors import SimError
from simrunner.run.log import write_log
from simrunner.run.result import RunResult


@dataclass(frozen=True)
class Outputs:
    """Where to write a run's outputs (None: not written)."""

    video: str | Path | None = None
    csv: str | Path | None = None
    plot: str | Path | None = None
    summary: str | Path | None = None


def write_outputs(result: RunResult, outputs: Outputs, video, track) -> None:
    """Close the video (``video``: the run's VideoRecorder or None) and write CSV, plot and
    summary. All are attempted; the first error is raised after the others were written.
    ``result.outputs`` names what was written."""
    errors: list[SimError] = []
    if video is not None:
        try:
            p = video.close()
            if p is not None:
                result.outputs["video"] = str(p)
        except SimError as exc:
            errors.append(exc)
    if outputs.csv is not None:
        try:
            result.outputs["csv"] = str(write_log(result.log, outputs.csv))
        except SimError as exc:
            errors.append(exc)
    if outputs.plot is not None:
        try:
            from simrunner.run.plot import plot_run

            result.outputs["plot"] = str(plot_run(result.log, track, outputs.plot,
                                                  title=plot_title(result)))
        except SimError as exc:
            errors.append(exc)
    if outputs.summary is not None:
        path = Path(outputs.summary)
        result.outputs["summary"] = str(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(json.dumps(result.summary(), indent=2) + "\n")
            os.replace(tmp, path)
        except OSError as exc:
            errors.append(SimError(f"{path}: cannot write summary ({exc.strerror})"))
    if errors:
        raise errors[0]


def plot_title(r: RunResult) -> str:
    laps = ", ".join(f"{t:.2f} s" for t in r.lap_times_s) or "none"
    return f"{Path(r.track).name}: {r.outcome}, laps {r.laps_completed}/{r.laps} ({laps})"
