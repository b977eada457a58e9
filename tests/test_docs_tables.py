"""The docs' bench tables are what tools/render_bench_tables.py renders from bench/results/*.json
(docs/gap.md, "The bench"), and its ``--check`` notices when they are not."""
from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "tools" / "render_bench_tables.py"
REGENERATE = "regenerate with `python tools/render_bench_tables.py`"


def run_script(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], cwd=REPO, capture_output=True, text=True,
                          timeout=60)


def load_script():
    spec = importlib.util.spec_from_file_location("render_bench_tables", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def copies(tmp_path):
    """A copy of the gap results and of docs/gap.md: (results dir, docs dir, results file, doc)."""
    results, docs = tmp_path / "results", tmp_path / "docs"
    results.mkdir()
    docs.mkdir()
    shutil.copy(REPO / "bench" / "results" / "gap.json", results / "gap.json")
    shutil.copy(REPO / "docs" / "gap.md", docs / "gap.md")
    return results, docs, results / "gap.json", docs / "gap.md"


def check(results: Path, docs: Path) -> subprocess.CompletedProcess:
    return run_script("--check", "--results", str(results), "--docs", str(docs))


def test_the_docs_bench_tables_are_current():
    done = run_script("--check")
    assert done.returncode == 0, f"{done.stdout}{done.stderr}{REGENERATE}"
    assert done.stdout == done.stderr == ""


def test_every_results_file_has_a_renderer_and_a_doc():
    module = load_script()
    for path in sorted((REPO / "bench" / "results").glob("*.json")):
        assert path.stem in module.RENDERERS, f"{path.name}: no renderer in tools/render_bench_tables.py"
        begin = module.markers(path.stem)[0]
        assert any(begin in doc.read_text() for doc in (REPO / "docs").glob("*.md")), f"no doc has {begin}"


def test_a_changed_figure_fails_the_check_naming_the_doc(copies):
    results, docs, gap_json, gap_md = copies
    assert check(results, docs).returncode == 0  # the copies are current, as the repository is
    data = json.loads(gap_json.read_text())
    row = next(r for r in data["rows"] if r["mode"] == "timing")
    row["value"] += 7.0  # 155 s -> 162 s
    gap_json.write_text(json.dumps(data, indent=1))

    done = check(results, docs)
    assert done.returncode == 1
    assert done.stdout == ""
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and "gap.md" in lines[0] and "not current" in lines[0], done.stderr
    assert "162 s" not in gap_md.read_text()  # --check writes nothing

    wrote = run_script("--results", str(results), "--docs", str(docs))
    assert wrote.returncode == 0 and "gap.md" in wrote.stdout
    text = gap_md.read_text()
    assert "| 162 s |" in text and "| 155 s |" not in text
    assert check(results, docs).returncode == 0
    outside = text.split("<!-- bench:gap begin -->")[0] + text.split("<!-- bench:gap end -->")[1]
    original = (REPO / "docs" / "gap.md").read_text()
    assert outside == original.split("<!-- bench:gap begin -->")[0] + original.split("<!-- bench:gap end -->")[1]


def test_a_block_edited_by_hand_fails_the_check(copies):
    results, docs, _, gap_md = copies
    gap_md.write_text(gap_md.read_text().replace("| timing |", "| timing (edited) |"))
    done = check(results, docs)
    assert done.returncode == 1 and "gap.md" in done.stderr


@pytest.mark.parametrize("spoil, message", [
    (lambda t: t.replace("<!-- bench:gap end -->", ""), "expected one"),
    (lambda t: t.replace("<!-- bench:gap begin -->", "").replace("<!-- bench:gap end -->", ""), "no doc"),
])
def test_markers_that_do_not_pair_up_are_bad_input(copies, spoil, message):
    results, docs, _, gap_md = copies
    gap_md.write_text(spoil(gap_md.read_text()))
    done = check(results, docs)
    assert done.returncode == 2 and message in done.stderr and len(done.stderr.splitlines()) == 1


def test_render_writes_the_figures_and_names_the_runs():
    module = load_script()
    data = {"format": module.RESULTS_FORMAT, "runs": {
        "a": {"command": "python -m bench.bench_gap --mode single", "date": "2027-01-02", "commit": "abc1234",
              "wall_min": 3.5, "jobs": 2, "note": ""}},
        "rows": [
            {"mode": "single", "trials": "0-3", "target": "named where SNR >= 3", "kind": "share", "value": 0.75,
             "n": 4, "detail": "", "goal": ">= 95 %", "met": False, "run": "a"},
            {"mode": "single", "trials": "0-3", "target": "median parameter error", "kind": "error",
             "value": 0.04, "n": 9, "detail": "", "goal": "<= 10 %", "met": True, "run": "a"},
            {"mode": "real", "trials": "", "target": "DS2: held-out position RMSE not worse", "kind": "ratio",
             "value": 0.492, "n": 1, "detail": "0.435 -> 0.214 m", "goal": "after/before <= 1", "met": True,
             "run": "a"},
            {"mode": "compare", "trials": "0-3", "target": "median wall time per log", "kind": "seconds",
             "value": 554.0, "n": 4, "goal": "reported", "met": None, "run": "a", "method": "chain"}]}
    text = module.render("gap", data)
    assert ("| single 0-3 | named where SNR >= 3; median parameter error | 75 % (3 of 4); 4 % (n = 9) | "
            ">= 95 %; <= 10 % | **no**; yes | 1 |") in text
    assert "| real: DS2 | held-out position RMSE not worse | 0.492 (0.435 -> 0.214 m) |" in text
    assert "| median wall time per log | 554 s | 1 |" in text
    assert "1. `python -m bench.bench_gap --mode single` (2027-01-02, commit abc1234, 3.5 min, 2 processes)" in text
    with pytest.raises(module.RenderError):
        module.render("nothing", data)
    with pytest.raises(module.RenderError):
        module.render("gap", {**data, "rows": [{**data["rows"][0], "run": "b"}]})


def test_the_bench_results_option_writes_what_the_renderer_reads(tmp_path):
    """``python -m bench.bench_gap ... --results`` after a run: its modes' targets replace
    those modes' rows, the other modes keep theirs (here on rows a timing run and a real run
    that failed would give, without running either)."""
    from bench.bench_gap import write_results

    module = load_script()
    path = tmp_path / "gap.json"
    shutil.copy(REPO / "bench" / "results" / "gap.json", path)
    before = json.loads(path.read_text())
    rows = [{"mode": "timing", "log_s": 60.0, "jobs": 2, "wall_s": 150.4},
            {"mode": "real", "log": "f1tenth_DS2.csv", "error": "Traceback (most recent call last): ..."}]
    write_results(path, rows, ["timing", "real"], ["--mode", "timing,real", "--results"], 200.0, 2)
    data = json.loads(path.read_text())
    new = [r for r in data["rows"] if r["mode"] in ("timing", "real")]
    assert [(r["target"], r["value"]) for r in new] == [("f1tenth_DS2.csv: no traceback", 0.0),
                                                         ("whole chain, 60-s log, 2 processes", 150.4)]
    assert [r for r in data["rows"] if r["mode"] not in ("timing", "real")] == \
        [r for r in before["rows"] if r["mode"] not in ("timing", "real")]
    run = data["runs"][new[0]["run"]]
    assert run["command"] == "python -m bench.bench_gap --mode timing,real --results" and run["wall_min"] == 3.3
    assert not any(r["run"] in ("real-ds2", "real-ds3", "timing") for r in data["rows"])
    assert set(data["runs"]) == {r["run"] for r in data["rows"]}
    text = module.render("gap", data)
    assert "| timing | whole chain, 60-s log, 2 processes | 150 s | <= 180 s | yes |" in text
    assert "| real: f1tenth_DS2.csv | no traceback | traceback | none | **no** |" in text


def test_the_video_and_batch_benches_write_what_their_renderers_read(tmp_path):
    """``bench.record.save`` (bench_video, bench_batch's short batches) writes the results format
    the script reads; the tables carry each figure, the target and the machine it was measured on."""
    from bench.record import RESULTS_FORMAT, save

    module = load_script()
    assert RESULTS_FORMAT == module.RESULTS_FORMAT
    path = save("video", {"repeat": 3, "target_rtf": 8.0, "runs": [
        {"run": "no video", "wall_s": 0.52, "rtf": 14.66, "cpu_s": 0.686, "loop_rtf": 42.1, "frames": None, "mb": None},
        {"run": "--video, one core", "wall_s": 0.9, "rtf": 8.51, "cpu_s": 0.893, "loop_rtf": 12.0,
         "frames": "192 @ 25 fps", "mb": 0.86}]}, results=tmp_path)
    text = module.render("video", json.loads(path.read_text()))
    assert "| no video | 0.52 | 14.7x | 0.69 |  |" in text
    assert "| --video, one core | 0.90 | 8.5x | 0.89 | 192 @ 25 fps, 0.9 MB |" in text
    assert ">= 8x real time" in text and "cores at a 1-minute load of" in text
    path = save("batch_short", {"repetitions": 7, "rows_identical": False, "target_ratio": 1.7, "figures": [
        {"how": "command", "one_worker_s": 1.72, "two_workers_s": 1.03, "ratio": 1.67}]}, results=tmp_path)
    text = module.render("batch_short", json.loads(path.read_text()))
    assert "| command | 1.72 | 1.03 | 1.67x |" in text and "2 workers: **no**" in text and ">= 1.7x" in text


def test_every_bench_that_saves_has_a_renderer():
    """A bench's ``save("NAME", ...)`` names a renderer (the NAMEs in bench/*.py, read as text)."""
    import re

    module = load_script()
    names = {m for path in (REPO / "bench").glob("bench_*.py")
             for m in re.findall(r"\bsave\(\s*\"(\w+)\"", path.read_text())}
    assert {"video", "batch_short", "batch", "closed_loop", "startup", "watch", "memory", "gym", "random",
            "c_controller"} <= names
    assert names <= set(module.RENDERERS), f"no renderer for {sorted(names - set(module.RENDERERS))}"


def test_the_other_recording_benches_write_what_their_renderers_read(tmp_path):
    """The tables of ``batch``, ``closed_loop``, ``startup``, ``watch``, ``memory``, ``gym``,
    ``random`` and ``c_controller`` carry each figure, its target and the machine it was measured on."""
    from bench.record import save

    module = load_script()

    def text(name: str, figures: dict) -> str:
        out = module.render(name, json.loads(save(name, figures, results=tmp_path).read_text()))
        assert "cores at a 1-minute load of" in out
        return out

    batch = {"runs": 48, "target_speedup": 1.8, "target_overhead": 0.05, "rows_identical": True,
             "workers": [{"workers": 1, "runs_per_s": 6.7, "laps_per_core_min": 404},
                         {"workers": 2, "runs_per_s": 14.5, "laps_per_core_min": 434}],
             "speedup": 2.164, "bare_ms": 145.2, "pool_ms": 148.6, "overhead": 0.022, "ray": None}
    out = text("batch", batch)
    assert "| 2 workers vs 1, steady | 14.5 vs 6.7 runs/s = 2.16x | >= 1.8x |" in out
    assert "| +2.2 % (149 vs 145 ms) | <= 5 % |" in out and "Ray not installed" in out
    out = text("batch", {**batch, "ray": {"repetitions": 3, "rows_identical": False, "target_change": 0.1,
                                          "figures": [{"what": "steady CPU", "ray_ms": 112.9, "local_ms": 108.7,
                                                       "change": 0.039}],
                                          "start": [{"how": "ray", "to_first_worker_s": 2.4, "to_ready_s": 3.1,
                                                     "after_last_row_s": 1.2}]}})
    assert "| steady CPU | 112.9 ms | 108.7 ms | +3.9 % |" in out and "| ray | 2.4 | 3.1 | 1.2 |" in out
    assert "<= +10 %" in out and "the pool: **no**" in out
    out = text("closed_loop", {"repeats": 5, "sim_s": 7.66, "frames": 383, "fps": 50.0, "rtf_target": 30.0,
                               "ratio_target": 0.8, "replay_exact": True, "ratio_replay": 0.82, "ratio_bare": 0.72,
                               "rows": [{"run": "closed", "rtf_cpu": 46.2, "us_per_frame": 432.7}]})
    assert "| 46.2x | 433 |" in out and "replay 0.82 (target >= 0.8)" in out and ">= 30x" in out
    out = text("startup", {"repeat": 5, "sim_s": 60.0, "target_factor": 35.0, "target_startup_s": 0.6,
                           "load_before": 0.2, "sixty": {"wall": 1.75, "cpu": 1.85, "loop": 1.43, "startup": 0.32},
                           "commands": [{"command": "simrunner --help", "median_s": 0.16, "min_s": 0.15,
                                         "max_s": 0.17}]})
    assert "| 1.75 (34.3x real time) | >= 35x |" in out and "| 0.32 | <= 0.6 s |" in out
    assert "| `simrunner --help` | 0.16 | 0.15 | 0.17 |" in out
    out = text("watch", {"repeat": 5, "target_s": 0.5, "outcomes": ["finished"],
                         "rows": [{"what": "wall", "median_s": 0.241, "min_s": 0.239, "max_s": 0.244}]})
    assert "| save -> result, wall | 0.24 | 0.24 | 0.24 |" in out and "target < 0.5 s" in out
    out = text("memory", {"keep_rows": 131072, "rows": [{"minutes": 60.0, "csv": True, "rows": 180001,
                                                         "log_rows": 131072, "peak_rss_mb": 283.4}]})
    assert "| 60 | yes | 180,001 | 131,072 | 283 |" in out
    out = text("gym", {"repeats": 3, "episode_s": 20.0, "steps": 1000, "target_steps_per_s": 2000.0,
                       "steps_per_s": 3580, "step_us": 279.3, "step_wall_us": 281.0, "replay_us": 220.4,
                       "physics_share": 0.789, "reset_ms": 1.31})
    assert "| 3,580 steps/s (279 us CPU, 281 us wall) | >= 2,000 steps/s |" in out and "(79 % of a step)" in out
    out = text("random", {"n": 2000, "target_per_s": 20.0, "per_cpu_s": 29.8, "per_wall_s": 25.1,
                          "attempts_mean": 1.52, "attempts_max": 8, "invalid": 0, "crossings": {"0": 2000}})
    assert "seeds 0-1,999" in out and "| 29.8 (25.1 per wall second) | >= 20 |" in out
    assert "| 0 of 2,000 | 0 |" in out
    out = text("c_controller", {
        "closed_loop": {"repeats": 24, "sim_s": 7.38, "ratio": 1.002, "ratio_median": 0.998,
                        "paired": [0.991, 0.996, 1.004], "ratio_isolate": 0.931,
                        "laps": [{"controller": "line_follower.c", "rtf_wall": 73.04, "rtf_wall_median": 71.6}]},
        "split": {"inside_ms": 98.71, "outside_py_ms": 2.4, "outside_c_ms": 2.1, "outside_diff_ms": [0.1, 0.3, 0.5],
                  "implied_ratio": 1.0029},
        "start_up": {"repeat": 3, "target_first_s": 3.0, "target_margin_s": 0.2,
                     "rows": [{"run": "C, new", "median_s": 1.234, "min_s": 1.2, "max_s": 1.3}]}})
    assert "| `line_follower.c` | 73.0x | 71.6x |" in out and "C / Python: 1.002 on the best laps" in out
    assert "(95 % interval 0.991-1.004); target >= 1" in out and "`--isolate` / Python: 0.931" in out
    assert "+0.300 ms, 95 % interval +0.100 to +0.500" in out and "| C, new | 1.23 | 1.20 | 1.30 |" in out
    assert "first run < 3 s" in out
