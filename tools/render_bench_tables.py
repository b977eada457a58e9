"""Render the benches' saved figures into the docs.

    python tools/render_bench_tables.py            (with the environment's interpreter)
    python tools/render_bench_tables.py --check    exit 1 when a doc is not what the render gives

Every ``bench/results/NAME.json`` that has a renderer (:data:`RENDERERS`) is rendered to a
markdown block, which replaces the text between ``<!-- bench:NAME begin -->`` and
``<!-- bench:NAME end -->`` in the docs (``docs/*.md``) that hold those markers. A bench
writes its JSON (``python -m bench.bench_gap ... --results``); this script is the only
writer of the blocks, so the docs show the saved figures and nothing else. Benches that record
their figures with ``bench.record.save`` (``video``, ``batch``, ``closed_loop``, ``startup``,
``watch``, ``memory``, ``gym``, ``random``, ``c_controller``) write this format too.

``--check`` writes nothing and prints one line per doc whose block differs (exit 1). Bad
input (a results file no doc has markers for, markers that do not pair up, a JSON in a
format the renderer does not know): one line, exit 2. ``--results DIR`` and ``--docs DIR``
point elsewhere (tests run it on copies).
"""
from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path
from typing import Callable

REPO = Path(__file__).resolve().parents[1]
RESULTS_DIR = REPO / "bench" / "results"
DOCS_DIR = REPO / "docs"
RESULTS_FORMAT = "nxpcup-bench-results/1"


class RenderError(ValueError):
    """A results file or a doc the script cannot handle (the message says which and why)."""


# --- figures -------------------------------------------------------------------------------------

def figure_text(row: dict) -> str:
    """A row's figure as the docs write it. ``kind``: ``share`` (``value`` of ``n``: "75 % (6
    of 8)"), ``error`` (a median relative error: "4 % (n = 9)"), ``ratio`` ("0.352"),
    ``seconds`` ("155 s") or ``text`` (``detail`` alone); ``detail`` follows the number in
    brackets. A ``value`` of null is "n/a"."""
    kind, value, n, detail = row["kind"], row.get("value"), row.get("n"), row.get("detail") or ""
    if kind == "text":
        return detail
    if value is None or not math.isfinite(value):
        text = "n/a" + (f" (n = {n})" if n is not None else "")
    elif kind == "share":
        text = f"{100 * value:.0f} %" + (f" ({round(value * n)} of {n})" if n else "")
    elif kind == "error":
        text = f"{100 * value:.0f} %" + (f" (n = {n})" if n else "")
    elif kind == "ratio":
        text = f"{value:.3g}" + (f" (n = {n})" if n and n > 1 else "")
    elif kind == "seconds":
        text = f"{value:.0f} s"
    else:
        raise RenderError(f"figure kind {kind!r}: expected share, error, ratio, seconds or text")
    return f"{text} ({detail})" if detail else text


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _met(met: bool | None) -> str:
    return "" if met is None else ("yes" if met else "**no**")


def _run_text(run: dict) -> str:
    parts = [run["date"], f"commit {run['commit']}"]
    if run.get("wall_min") is not None:
        parts.append(f"{run['wall_min']:g} min")
    if run.get("jobs") is not None:
        parts.append(f"{run['jobs']} processes")
    note = f"; {run['note']}" if run.get("note") else ""
    return f"`{run['command']}` ({', '.join(parts)}{note})"


def render_gap(data: dict) -> str:
    """``bench/results/gap.json`` (written by ``python -m bench.bench_gap --results``): the
    per-mode table (a row per mode, run and subject: its targets, figures, goals and whether
    each is met, ``; ``-separated in target order; a target ``SUBJECT: what`` goes to its
    subject's row, the subject named in the mode cell), one side-by-side table per mode whose
    rows carry a ``method``, and the numbered list of the runs (command, date, commit, wall
    time, note)."""
    runs, rows = data["runs"], data["rows"]
    order: list[str] = []  # run ids, numbered by first use

    def run_no(row: dict) -> int:
        rid = row["run"]
        if rid not in runs:
            raise RenderError(f"row {row['target']!r}: run {rid!r} is not in runs")
        if rid not in order:
            order.append(rid)
        return order.index(rid) + 1

    def mode_of(row: dict) -> str:
        return f"{row['mode']} {row.get('trials') or ''}".strip()

    groups: dict[tuple[str, int, str], list[dict]] = {}
    for row in rows:  # a target "SUBJECT: what" (a log, a car, ...) joins the row of its subject
        if "method" not in row:
            subject = row["target"].split(": ", 1)[0] if ": " in row["target"] else ""
            groups.setdefault((mode_of(row), run_no(row), subject), []).append(row)
    lines = ["| mode | targets | figures | goals | met | run |", "| --- | --- | --- | --- | --- | --- |"]
    for (mode, no, subject), group in groups.items():
        targets = [r["target"][len(subject) + 2:] if subject else r["target"] for r in group]
        mode = f"{mode}: {subject}" if subject else mode
        cells = [targets, [figure_text(r) for r in group],
                 [r.get("goal", "") for r in group], [_met(r.get("met")) for r in group]]
        lines.append(f"| {_cell(mode)} | " + " | ".join(_cell("; ".join(c)) for c in cells) + f" | {no} |")
    side: dict[str, list[dict]] = {}
    for row in rows:
        if "method" in row:
            side.setdefault(mode_of(row), []).append(row)
    for mode, group in side.items():
        methods = list(dict.fromkeys(r["method"] for r in group))
        targets = list(dict.fromkeys(r["target"] for r in group))
        cells = {(r["target"], r["method"]): r for r in group}
        lines += ["", f"| {_cell(mode)}, side by side | " + " | ".join(_cell(m) for m in methods) + " | run |",
                  "| --- | " + " | ".join("---" for _ in methods) + " | --- |"]
        for target in targets:
            here = [cells.get((target, m)) for m in methods]
            nos = sorted({run_no(r) for r in here if r is not None})
            lines.append(f"| {_cell(target)} | "
                         + " | ".join(_cell(figure_text(r)) if r is not None else "" for r in here)
                         + f" | {', '.join(map(str, nos))} |")
    lines += ["", "The runs (column `run`):"]
    lines += [f"{i}. {_run_text(runs[rid])}" for i, rid in enumerate(order, start=1)]
    return "\n".join(lines)


def _machine(data: dict) -> str:
    m = data.get("machine", {})
    load = m.get("load_1min")
    return (f"{m.get('cpus', '?')} cores at a 1-minute load of {'?' if load is None else load}, "
            f"Python {m.get('python', '?')}")


def render_video(data: dict) -> str:
    """``bench/results/video.json`` (``python -m bench video``): a row per run (wall, real-time
    factor, CPU, the video's frames and size), the target and what it was measured on."""
    f = data["figures"]
    lines = ["| `simrunner drive examples/line_follower.py`, one lap | wall s | real-time factor | CPU s | video |",
             "| --- | --- | --- | --- | --- |"]
    for r in f["runs"]:
        video = "" if r["frames"] is None else f"{r['frames']}, {r['mb']:.1f} MB"
        lines.append(f"| {_cell(r['run'])} | {r['wall_s']:.2f} | {r['rtf']:.1f}x | {r['cpu_s']:.2f} | {video} |")
    lines += ["", f"Whole processes, the best of {f['repeat']}; target with `--video` on one core: "
                  f">= {f['target_rtf']:g}x real time. Measured on {_machine(data)}."]
    return "\n".join(lines)


def render_batch_short(data: dict) -> str:
    """``bench/results/batch_short.json`` (``python -m bench batch``, its short batches): 1 and
    2 workers and their ratio for each way of timing, whether the rows were identical."""
    f = data["figures"]
    lines = ["| 8 one-lap runs | 1 worker s | 2 workers s | 2 workers / 1 |", "| --- | --- | --- | --- |"]
    for r in f["figures"]:
        lines.append(f"| {_cell(r['how'])} | {r['one_worker_s']:.2f} | {r['two_workers_s']:.2f} | {r['ratio']:.2f}x |")
    lines += ["", f"The best of {f['repetitions']} alternating repetitions; rows identical with 1 and 2 workers: "
                  f"{'yes' if f['rows_identical'] else '**no**'}; target >= {f['target_ratio']:g}x. "
                  f"Measured on {_machine(data)}."]
    return "\n".join(lines)


def _pct(share: float) -> str:
    """A relative change as the docs write it: "+3.9 %"."""
    return f"{100 * share:+.1f} %"


def render_batch(data: dict) -> str:
    """``bench/results/batch.json`` (``python -m bench batch``, its longer batches): 1 and 2
    workers' steady rates, the pool's per-run overhead, and Ray against the local pool."""
    f = data["figures"]
    one, two = f["workers"]
    lines = [f"| {f['runs']} one-lap runs | figure | target |", "| --- | --- | --- |",
             f"| 2 workers vs 1, steady | {two['runs_per_s']:.1f} vs {one['runs_per_s']:.1f} runs/s = "
             f"{f['speedup']:.2f}x | >= {f['target_speedup']:g}x |",
             f"| laps per core-minute, 1 and 2 workers | {one['laps_per_core_min']}, {two['laps_per_core_min']} | |",
             f"| per-run overhead of the pool (1 worker) vs bare `drive()` | {_pct(f['overhead'])} "
             f"({f['pool_ms']:.0f} vs {f['bare_ms']:.0f} ms) | <= {100 * f['target_overhead']:g} % |"]
    notes = [f"rows identical with 1 and 2 workers: {'yes' if f['rows_identical'] else '**no**'}"]
    ray = f.get("ray")
    if ray is not None:
        lines += ["", f"| per run, median of {ray['repetitions']} | Ray local cluster | local pool | Ray |",
                  "| --- | --- | --- | --- |"]
        for r in ray["figures"]:
            lines.append(f"| {_cell(r['what'])} | {r['ray_ms']:.1f} ms | {r['local_ms']:.1f} ms | "
                         f"{_pct(r['change'])} |")
        lines += ["", "| 2 workers, median s after the batch's start | first worker started | all ready | "
                      "end after the last row |", "| --- | --- | --- | --- |"]
        for r in ray["start"]:
            lines.append(f"| {_cell(r['how'])} | {r['to_first_worker_s']:.1f} | {r['to_ready_s']:.1f} | "
                         f"{r['after_last_row_s']:.1f} |")
        notes.append(f"Ray's target: steady CPU <= {100 * ray['target_change']:+g} %; rows identical for Ray "
                     f"and the pool: {'yes' if ray['rows_identical'] else '**no**'}")
    else:
        notes.append("Ray not installed: no Ray figures")
    lines += ["", "; ".join(notes) + f". Measured on {_machine(data)}."]
    return "\n".join(lines)


def _seconds_rows(rows: list[dict], key: str) -> list[str]:
    """Table rows ``| label | median | min | max |`` of rows with ``median_s``, ``min_s``, ``max_s``."""
    return [f"| {_cell(r[key])} | {r['median_s']:.2f} | {r['min_s']:.2f} | {r['max_s']:.2f} |" for r in rows]


def render_startup(data: dict) -> str:
    """``bench/results/startup.json`` (``python -m bench startup``): 60 simulated seconds as a
    whole process (its real-time factor and start-up against their targets), and the commands'
    wall times in fresh processes."""
    f = data["figures"]
    six = f["sixty"]
    factor = f["sim_s"] / six["wall"]
    lines = [f"| {f['sim_s']:g} simulated s of `line_follower.py`, default track | median s | target |",
             "| --- | --- | --- |",
             f"| whole process, wall | {six['wall']:.2f} ({factor:.1f}x real time) | >= {f['target_factor']:g}x |",
             f"| start-up (whole process - run loop) | {six['startup']:.2f} | <= {f['target_startup_s']:g} s |",
             f"| run loop | {six['loop']:.2f} | |",
             f"| whole process, CPU | {six['cpu']:.2f} | |",
             "", "| command, fresh process | median s | min | max |", "| --- | --- | --- | --- |"]
    lines += _seconds_rows([{**r, "command": f"`{r['command']}`"} for r in f["commands"]], "command")
    lines += ["", f"{f['repeat']} fresh processes each, after one untimed run where a cache matters; "
                  f"targets for an idle machine. Measured on {_machine(data)}."]
    return "\n".join(lines)


def render_watch(data: dict) -> str:
    """``bench/results/watch.json`` (``python -m bench watch``): save-to-result turnaround of
    ``drive --watch`` (wall, CPU, the lap's loop) and its target."""
    f = data["figures"]
    what = {"wall": "save -> result, wall", "cpu": "the same, CPU", "loop": "of which the lap's loop, wall"}
    lines = ["| `drive --watch`, one lap of the default track | median s | min | max |",
             "| --- | --- | --- | --- |"]
    lines += _seconds_rows([{**r, "what": what.get(r["what"], r["what"])} for r in f["rows"]], "what")
    lines += ["", f"{f['repeat']} saves; target < {f['target_s']:g} s (wall); outcomes: "
                  f"{', '.join(f['outcomes'])}. Measured on {_machine(data)}."]
    return "\n".join(lines)


def render_closed_loop(data: dict) -> str:
    """``bench/results/closed_loop.json`` (``python -m bench closed_loop``): the closed-loop lap
    and its baselines (real-time factor and CPU a frame), the ratios and their targets."""
    f = data["figures"]
    what = {"closed": "closed loop (physics, camera, controller, judge, telemetry)",
            "replay": "`replay`: the lap's commands on a fresh sim", "speed": "straight, the lap's speed commands",
            "bare": "`bare`: `CarSim.step` on a steady circle"}
    lines = [f"| one lap of `line_follower.py`, default track ({f['sim_s']:g} s, {f['frames']} frames) "
             "| real-time factor (CPU) | CPU us a frame |", "| --- | --- | --- |"]
    for r in f["rows"]:
        lines.append(f"| {_cell(what.get(r['run'], r['run']))} | {r['rtf_cpu']:.1f}x | {r['us_per_frame']:.0f} |")
    lines += ["", f"Closed loop / replay {f['ratio_replay']:.2f} (target >= {f['ratio_target']:g}), closed loop / "
                  f"steady circle {f['ratio_bare']:.2f}; real-time factor target >= {f['rtf_target']:g}x; the replay "
                  f"ends at the lap's pose exactly: {'yes' if f['replay_exact'] else '**no**'}. Best of "
                  f"{f['repeats']}, process CPU time. Measured on {_machine(data)}."]
    return "\n".join(lines)


def render_memory(data: dict) -> str:
    """``bench/results/memory.json`` (``python -m bench memory``): the peak RSS of whole ``drive``
    processes by simulated length, with and without ``--csv``."""
    f = data["figures"]
    lines = ["| simulated minutes | `--csv` | rows | rows kept in memory | peak RSS MB |",
             "| --- | --- | --- | --- | --- |"]
    for r in f["rows"]:
        lines.append(f"| {r['minutes']:g} | {'yes' if r['csv'] else 'no'} | {r['rows']:,} | {r['log_rows']:,} | "
                     f"{r['peak_rss_mb']:.0f} |")
    lines += ["", f"`line_follower.py` on the default track, one fresh process a row; at most {f['keep_rows']:,} "
                  f"rows kept in memory. Measured on {_machine(data)}."]
    return "\n".join(lines)


def render_gym(data: dict) -> str:
    """``bench/results/gym.json`` (``python -m bench gym``): ``env.step`` per CPU-second against
    the target, the physics' share of a step, a reset."""
    f = data["figures"]
    lines = [f"| `NXPCup-v0`, {f['episode_s']:g}-s episodes of a line follower ({f['steps']} steps) "
             "| figure | target |",
             "| --- | --- | --- |",
             f"| `env.step`, one core | {f['steps_per_s']:,} steps/s ({f['step_us']:.0f} us CPU, "
             f"{f['step_wall_us']:.0f} us wall) | >= {f['target_steps_per_s']:,.0f} steps/s |",
             f"| the same commands replayed on a bare car model | {f['replay_us']:.0f} us "
             f"({100 * f['physics_share']:.0f} % of a step) | |",
             f"| `reset` on the same track | {f['reset_ms']:.2f} ms CPU | |",
             "", f"Best of {f['repeats']}, process CPU time. Measured on {_machine(data)}."]
    return "\n".join(lines)


def render_random(data: dict) -> str:
    """``bench/results/random.json`` (``python -m bench random``): layouts per CPU- and wall
    second, attempts per layout, crossings drawn, layouts failing the full validation."""
    f = data["figures"]
    crossings = ", ".join(f"{v:,} with {k}" for k, v in f["crossings"].items())
    lines = [f"| `random_layout`, seeds 0-{f['n'] - 1:,} | figure | target |", "| --- | --- | --- |",
             f"| layouts per CPU-second | {f['per_cpu_s']:.1f} ({f['per_wall_s']:.1f} per wall second) | "
             f">= {f['target_per_s']:g} |",
             f"| candidates per layout | {f['attempts_mean']:.2f} on average, at most {f['attempts_max']} | |",
             f"| layouts by crossings | {crossings} | |",
             f"| failing `trackgen validate` (meshes included) | {f['invalid']:,} of {f['n']:,} | 0 |",
             "", f"Measured on {_machine(data)}."]
    return "\n".join(lines)


def render_c_controller(data: dict) -> str:
    """``bench/results/c_controller.json`` (``python -m bench c_controller``): the closed-loop laps
    of the C and the Python line follower (real-time factors, C / Python and its paired
    interval), their split inside / outside the Spinner calls, and ``simrunner drive``'s
    start-up with each against the targets."""
    f, sp, up = data["figures"]["closed_loop"], data["figures"]["split"], data["figures"]["start_up"]
    lo, mid, hi = f["paired"]
    d_lo, d_mid, d_hi = sp["outside_diff_ms"]
    lines = [f"| one lap of the default track ({f['sim_s']:g} s), {f['repeats']} laps each | real-time factor, best "
             "| median |", "| --- | --- | --- |"]
    for r in f["laps"]:
        lines.append(f"| `{_cell(r['controller'])}` | {r['rtf_wall']:.1f}x | {r['rtf_wall_median']:.1f}x |")
    lines += ["", f"C / Python: {f['ratio']:.3f} on the best laps, {f['ratio_median']:.3f} on the medians, "
                  f"{mid:.3f} the median of the paired laps (95 % interval {lo:.3f}-{hi:.3f}); target >= 1. "
                  f"`--isolate` / Python: {f['ratio_isolate']:.3f}. Split: {sp['inside_ms']:.1f} ms a lap inside the "
                  f"Spinner calls; outside them Python {sp['outside_py_ms']:.2f} ms, C {sp['outside_c_ms']:.2f} ms "
                  f"(Python - C, paired: {d_mid:+.3f} ms, 95 % interval {d_lo:+.3f} to {d_hi:+.3f}), which makes "
                  f"C / Python {sp['implied_ratio']:.4f}.",
              "", "| `simrunner drive ... --laps 1`, fresh process | median s | min | max |",
              "| --- | --- | --- | --- |"]
    lines += _seconds_rows(up["rows"], "run")
    lines += ["", f"Targets: a new C controller's first run < {up['target_first_s']:g} s; a cached one within "
                  f"{up['target_margin_s']:g} s of Python. Measured on {_machine(data)}."]
    return "\n".join(lines)


RENDERERS: dict[str, Callable[[dict], str]] = {"gap": render_gap, "gap_duty": render_gap,  # the same layout
                                               "video": render_video, "batch_short": render_batch_short,
                                               "batch": render_batch, "closed_loop": render_closed_loop,
                                               "startup": render_startup, "watch": render_watch,
                                               "memory": render_memory, "gym": render_gym, "random": render_random,
                                               "c_controller": render_c_controller}


def render(name: str, data: dict) -> str:
    """The markdown block of results file ``name`` (its stem) holding ``data``; what goes
    between the doc's markers (without them)."""
    if name not in RENDERERS:
        raise RenderError(f"bench results {name!r}: no renderer (expected one of {', '.join(RENDERERS)})")
    if data.get("format") != RESULTS_FORMAT:
        raise RenderError(f"bench results {name!r}: format {data.get('format')!r}, expected {RESULTS_FORMAT!r}")
    try:
        return RENDERERS[name](data)
    except (KeyError, TypeError, AttributeError) as exc:
        raise RenderError(f"bench results {name!r}: a run or row lacks a field or has the wrong type ({exc!r})") from None


# --- docs ----------------------------------------------------------------------------------------------

def markers(name: str) -> tuple[str, str]:
    return f"<!-- bench:{name} begin -->", f"<!-- bench:{name} end -->"


def replaced(text: str, name: str, block: str, where: str = "the doc") -> str:
    """``text`` with what stands between ``name``'s markers replaced by ``block``."""
    begin, end = markers(name)
    if text.count(begin) != 1 or text.count(end) != 1 or text.index(begin) > text.index(end):
        raise RenderError(f"{where}: expected one {begin} before one {end}")
    head, rest = text.split(begin)
    _, tail = rest.split(end)
    return f"{head}{begin}\n{block}\n{end}{tail}"


def updates(results_dir: Path, docs_dir: Path) -> list[tuple[Path, str, str]]:
    """``(doc, its text, its text rendered)`` for every doc the render changes."""
    docs = {p: p.read_text(encoding="utf-8") for p in sorted(docs_dir.glob("*.md"))}
    new = dict(docs)
    for path in sorted(results_dir.glob("*.json")):
        name = path.stem
        if name not in RENDERERS:
            continue
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise RenderError(f"{path}:{exc.lineno}: {exc.msg}") from None
        block = render(name, data)
        begin = markers(name)[0]
        holders = [doc for doc, text in new.items() if begin in text]
        if not holders:
            raise RenderError(f"{path}: no doc in {docs_dir} has {begin}")
        for doc in holders:
            new[doc] = replaced(new[doc], name, block, str(doc))
    # a doc with markers for a results file that does not exist
    for doc, text in docs.items():
        for name in re.findall(r"<!-- bench:([\w-]+) begin -->", text):
            if not (results_dir / f"{name}.json").exists():
                raise RenderError(f"{doc}: {markers(name)[0]} but no {results_dir / (name + '.json')}")
    return [(doc, docs[doc], new[doc]) for doc in docs if new[doc] != docs[doc]]


def _shown(path: Path) -> str:
    try:
        return path.resolve().relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return str(path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="render bench/results/*.json into the docs' bench tables")
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 when a doc is not current")
    ap.add_argument("--results", type=Path, default=RESULTS_DIR, metavar="DIR", help="the results folder")
    ap.add_argument("--docs", type=Path, default=DOCS_DIR, metavar="DIR", help="the docs folder")
    a = ap.parse_args(sys.argv[1:] if argv is None else argv)
    try:
        found = updates(a.results, a.docs)
    except (RenderError, OSError) as exc:
        print(f"render_bench_tables: {exc}", file=sys.stderr)
        return 2
    for doc, _, new in found:
        if a.check:
            print(f"{_shown(doc)}: bench tables are not current (run python tools/render_bench_tables.py)",
                  file=sys.stderr)
        else:
            doc.write_text(new, encoding="utf-8")
            print(f"{_shown(doc)}: bench tables rendered")
    return 1 if (a.check and found) else 0


if __name__ == "__main__":
    sys.exit(main())
