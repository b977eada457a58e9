"""The gap workflow's thresholds live in one settings object, each with its unit and how it
was derived (issue 48, item 1), passed down from ``run_gap`` (no module globals to patch)."""
from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.workflows.gap import GapError
from simrunner.workflows.gap.settings import SETTINGS, THRESHOLDS_SCRIPT, GapSettings, load_settings

GAP = Path(__file__).resolve().parents[1] / "simrunner" / "workflows" / "gap"
PHYSICAL = {"GRAVITY_MPS2"}  # physical constants, cited where defined


def test_every_setting_says_its_unit_and_derivation():
    rows = SETTINGS.describe()
    assert len(rows) > 80
    for name, value, unit, derived, script, shared in rows:
        assert unit and len(derived) > 10, name
        assert isinstance(shared, bool)
    calibrated = {r[0] for r in rows if r[4] == THRESHOLDS_SCRIPT}
    assert {"delta_bic_min", "improvement_min", "held_improvement_min", "safety"} <= calibrated
    # an override of the calibration states its reason at the value
    assert all("Override" in r[3] for r in rows if r[0] in ("delta_bic_min", "improvement_min"))
    assert {r[0] for r in rows if r[5]} >= {"aligned_share", "max_effects"}   # shaped by DS2/DS3


def _literal(node) -> bool:
    if isinstance(node, ast.Constant):
        return isinstance(node.value, (int, float)) and not isinstance(node.value, bool)
    if isinstance(node, ast.UnaryOp):
        return _literal(node.operand)
    if isinstance(node, ast.BinOp):
        return _literal(node.left) and _literal(node.right)
    if isinstance(node, ast.Dict):
        return any(_literal(v) for v in node.values)
    return False


def test_no_gap_module_defines_a_number_of_its_own():
    """A module-level number in the workflow comes from SETTINGS (synth.py makes the synthetic
    logs of tests and the bench: its numbers describe those logs, not the workflow)."""
    found = []
    for path in sorted(GAP.glob("*.py")):
        if path.name in ("settings.py", "synth.py"):
            continue
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
            value = getattr(node, "value", None)
            for t in targets:
                if isinstance(t, ast.Name) and value is not None and _literal(value) and t.id not in PHYSICAL:
                    found.append(f"{path.name}: {t.id}")
    assert not found, found


def _functions(tree: ast.AST):
    return [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


def _takes_settings(fn) -> bool:
    a = fn.args
    return any(x.arg == "settings" for x in a.posonlyargs + a.args + a.kwonlyargs)


def test_no_module_of_the_gap_workflow_holds_a_threshold_of_its_own():
    """Every number the workflow decides with is a field of GapSettings: no module-level
    alias (``NAME = SETTINGS.x``) that a test or a caller could patch instead of passing."""
    for path in sorted(GAP.glob("*.py")):
        text = path.read_text()
        assert not re.search(r"^[A-Za-z_][A-Za-z0-9_]* = .*SETTINGS\.", text, re.M), path.name


def test_every_call_inside_the_workflow_passes_its_settings_on():
    """A function that reads thresholds takes ``settings``; a caller in ``gap/`` that has
    settings in scope (its own parameter, ``self.settings``, a ``Problem``'s) passes them on, so
    a run's settings reach every stage and none silently falls back to the defaults."""
    trees = {p.name: ast.parse(p.read_text()) for p in sorted(GAP.glob("*.py"))}
    position = {}  # callee -> index of its positional settings parameter (None: keyword-only)
    for tree in trees.values():
        for fn in _functions(tree):
            if _takes_settings(fn):
                names = [x.arg for x in fn.args.posonlyargs + fn.args.args]
                position[fn.name] = names.index("settings") - (names[:1] == ["self"]) if "settings" in names else None
    assert {"check_measured", "find_glitches", "derive", "check_conventions", "make_windows", "replay",
            "segment", "leftovers", "pool_short_runs"} <= set(position)
    missing = []
    for name, tree in trees.items():
        for fn in _functions(tree):
            has = (_takes_settings(fn)
                   or any(isinstance(n, ast.Name) and n.id == "settings" and isinstance(n.ctx, ast.Store)
                          for n in ast.walk(fn))
                   or any(isinstance(n, ast.Attribute) and n.attr == "settings" for n in ast.walk(fn))
                   or any("Problem" in ast.unparse(x.annotation) for x in fn.args.args if x.annotation))
            if not has:
                continue
            for call in (n for n in ast.walk(fn) if isinstance(n, ast.Call)):
                callee = call.func.id if isinstance(call.func, ast.Name) else getattr(call.func, "attr", None)
                if callee not in position or any(k.arg in ("settings", None) for k in call.keywords):
                    continue
                if position[callee] is None or len(call.args) <= position[callee]:
                    missing.append(f"{name}:{call.lineno} {fn.name} -> {callee}")
    assert missing == []


def test_run_gap_uses_the_settings_it_is_given():
    """A run's settings decide: the same log with ``max_effects = 0`` tries nothing, and a
    window length from the settings lays the windows (run_gap's keywords override fields)."""
    from simrunner.workflows.gap.synth import make_measured_log
    from simrunner.workflows.gap.workflow import run_gap

    log, _ = make_measured_log("steering_offset", rng=np.random.default_rng(3), value=-0.03, duration_s=20.0)
    none = run_gap(log, jobs=1, effects=["steering_offset"], settings=dataclasses.replace(SETTINGS, max_effects=0))
    assert none.effects == [] and none.chain.stop_reason == "max effects 0: nothing tried"
    # the screening section says why it is empty (was a table header over no rows)
    from simrunner.workflows.gap.report import summary_text
    text = summary_text(none).splitlines()
    at = text.index("first step, every candidate screened (one parameter, the others nominal):")
    assert text[at + 1] == "  none: the chain ended before its first step was done (max effects 0: nothing tried)"
    assert none.gap_settings.max_effects == 0 and none.settings["max_effects"] == 0
    long = run_gap(log, jobs=1, effects=["steering_offset"],
                   settings=dataclasses.replace(SETTINGS, window_s=4.0, max_effects=0))
    assert long.settings["window_s"] == 4.0
    n_long = sum(len(p.fit_windows) + len(p.held_windows) for p in long.parts)
    n_default = sum(len(p.fit_windows) + len(p.held_windows) for p in none.parts)
    assert n_long < n_default
    again = run_gap(log, jobs=1, effects=["steering_offset"], settings=dataclasses.replace(SETTINGS, window_s=4.0),
                    max_effects=0)
    assert again.gap_settings == long.gap_settings


def test_a_settings_file_changes_named_fields_and_refuses_bad_ones(tmp_path):
    good = tmp_path / "slow_car.toml"
    good.write_text("# a slow car\nmoving_mps = 0.05\nmax_effects = 3\nwindow_s = 3\n")
    s = load_settings(good)
    assert s.changed() == {"moving_mps": 0.05, "max_effects": 3, "window_s": 3.0}
    assert (s.moving_mps, s.max_effects, s.window_s) == (0.05, 3, 3.0) and isinstance(s.window_s, float)
    assert dataclasses.replace(s, moving_mps=SETTINGS.moving_mps, max_effects=SETTINGS.max_effects,
                               window_s=SETTINGS.window_s) == GapSettings()
    for text, expected in (("moving_mps = 0.1\nmoving_mp = 2\n", r":2: unknown gap setting 'moving_mp' \(did you mean moving_mps\?\)"),
                           ("max_effects = 2.5\n", r":1: max_effects = 2.5: expected an integer >= 0"),
                           ("window_s = \"2\"\n", r":1: window_s = '2': expected a number > 0"),
                           ("window_s = -1.0\n", r":1: window_s = -1.0: expected a number > 0"),
                           ("holdout_every = 0\n", r":1: holdout_every = 0: expected an integer > 0"),
                           ("[moving_mps]\nx = 1\n", r":1: moving_mps = \{'x': 1\}: expected a number > 0"),
                           ("window_s = \n", r": invalid TOML: .*line 1")):
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(GapError, match=re.escape(str(bad)) + expected):
            load_settings(bad)


def test_simrunner_gap_reads_a_settings_file_and_says_what_is_wrong_with_one(tmp_path):
    from simrunner.cli import main

    bad = tmp_path / "gap.toml"
    bad.write_text("jump_zz = 3\n")
    log = tmp_path / "log.csv"
    log.write_text("t_s,speed_cmd_mps,steer_cmd_rad,speed_mps\n0,0,0,0\n")
    r = CliRunner().invoke(main, ["gap", str(log), "-o", str(tmp_path / "out"), "--settings", str(bad)])
    assert r.exit_code == 2 and "Traceback" not in r.output
    assert f"{bad}:1: unknown gap setting 'jump_zz' (did you mean jump_z?)" in r.output
    assert not (tmp_path / "out").exists()


def test_the_gap_car_is_named_after_its_car_file(tmp_path):
    """Issue 50 (cosmetic): the car.toml of ``--car team.toml`` (a file without a ``name``) was
    named nxp_cup_car, the built-in car's name; it is named after the file now."""
    from simrunner.cli.gap import named_after_file
    from vehicle.description import load_car

    team = tmp_path / "team.toml"
    team.write_text("[chassis]\nmass_kg = 1.3\n")
    named = tmp_path / "named.toml"
    named.write_text('name = "blue_car"\n')
    assert named_after_file(load_car(team), team).name == "team"
    assert named_after_file(load_car(named), named).name == "blue_car"
    assert named_after_file(load_car(None), None).name == "nxp_cup_car"
