"""The gap workflow's thresholds live in one settings object, each with its unit and how it
was derived (issue 48, item 1)."""
from __future__ import annotations

import ast
from pathlib import Path

from simrunner.workflows.gap import chain, fit, glitches, regimes, replay
from simrunner.workflows.gap.settings import SETTINGS, THRESHOLDS_SCRIPT

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


def test_shared_constants_have_one_value():
    assert glitches.MOVING_MPS == regimes.MOVING_MPS == replay.MOVING_MPS == SETTINGS.moving_mps
    assert replay.NO_DRIVE_CMD_MPS == regimes.COAST_CMD_MPS == SETTINGS.coast_cmd_mps
    assert chain.SAFETY == SETTINGS.safety and fit.DELTA_BIC_MIN == SETTINGS.delta_bic_min


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
