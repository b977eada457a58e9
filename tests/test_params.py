"""Controller parameters: ``--param NAME=VALUE`` parsing (table + property), conversion to
the default's type, ``RunSettings.params`` read-only, ``spinner.param`` inside a run, the
warning for a parameter never read, bad input as one line (exit 2)."""
from __future__ import annotations

import textwrap

import pytest
from click.testing import CliRunner
from hypothesis import given, strategies as st

from simrunner.cli import main as cli
from simrunner.errors import CommandError
from simrunner.run.params import ParamError, convert, parse_param, parse_params, parse_value
from simrunner.run.runner import drive
from simrunner.run.settings import RunSettings


@pytest.mark.parametrize("text, value", [
    ("3", 3), ("-2", -2), ("+7", 7), ("1.5", 1.5), ("2e-3", 0.002), (".5", 0.5), ("3.", 3.0),
    ("left", "left"), ("nan", "nan"), ("inf", "inf"), ("1.5x", "1.5x"), ("", ""), ("a=b", "a=b"),
])
def test_parse_value_table(text, value):
    got = parse_value(text)
    assert got == value and type(got) is type(value)


@given(st.integers(-10**12, 10**12))
def test_parse_value_ints_round_trip(n):
    assert parse_value(str(n)) == n and type(parse_value(str(n))) is int


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_parse_value_floats_round_trip(x):
    got = parse_value(repr(x))
    assert got == x


@pytest.mark.parametrize("item, match", [
    ("speed", "expected NAME=VALUE"), ("=3", "expected a name"), ("1x=3", "expected a name"),
    ("a b=3", "expected a name"),
])
def test_parse_param_errors(item, match):
    with pytest.raises(ParamError, match=match):
        parse_param(item)


def test_parse_params_duplicate_and_settings_read_only():
    assert parse_params(["a=1", "b = x", "c=2.5"]) == {"a": 1, "b": " x", "c": 2.5}
    with pytest.raises(ParamError, match="given twice"):
        parse_params(["a=1", "a=2"])
    s = RunSettings(params={"a": 1})
    with pytest.raises(TypeError):
        s.params["a"] = 2
    assert RunSettings().params == {}
    with pytest.raises(ParamError, match="expected an int, float or str"):
        RunSettings(params={"a": [1]})


@pytest.mark.parametrize("value, default, expected", [
    (3, 1.0, 3.0), (2.5, 1.0, 2.5), (3, 1, 3), (3.0, 1, 3), ("true", False, True), (0, True, False),
    ("no", True, False), (1.5, "x", "1.5"), ("left", "x", "left"), (2, None, 2), ("s", None, "s"),
])
def test_convert_table(value, default, expected):
    got = convert("p", value, default)
    assert got == expected and type(got) is type(expected)


@pytest.mark.parametrize("value, default", [(2.5, 1), ("fast", 0.8), ("maybe", False), (1, [1])])
def test_convert_refuses(value, default):
    with pytest.raises(CommandError, match="param"):
        convert("p", value, default)


def _ctl(tmp_path, body: str):
    path = tmp_path / "ctl.py"
    path.write_text(textwrap.dedent(body))
    return path


def test_param_reaches_the_controller_and_unused_are_reported(tmp_path):
    seen = []

    def main(spinner):
        seen.append((spinner.param("v", 0.5), spinner.param("n", 1), spinner.param("missing", "d")))
        spinner.set_speed_and_servo(seen[0][0], 0.0)
        spinner.sleep(0.1)

    r = drive(main, params={"v": 1, "n": 4, "typo": 3}, time_limit_s=1)
    assert r.outcome == "controller_returned"
    assert seen == [(1.0, 4, "d")] and type(seen[0][0]) is float
    assert r.unused_params == ("typo",)
    ctl = _ctl(tmp_path, """
        def main(spinner):
            spinner.set_speed_and_servo(spinner.param("v", 0.5), 0.0)
            spinner.sleep(0.1)
    """)
    res = CliRunner().invoke(cli, ["drive", str(ctl), "--param", "v=1", "--param", "typo=2",
                                   "--time-limit", "1"])
    assert res.exit_code == 0, res.output
    assert "never read --param typo" in res.output


def test_bad_value_is_a_controller_error_and_bad_option_exit_2(tmp_path):
    ctl = _ctl(tmp_path, """
        def main(spinner):
            spinner.param("kp", 0.8)
    """)
    r = drive(ctl, params={"kp": "fast"}, time_limit_s=1)
    assert r.outcome == "controller_error" and "param kp='fast'" in r.message
    assert "ctl.py" in r.error.traceback_text
    res = CliRunner().invoke(cli, ["drive", str(ctl), "--param", "kp"])
    assert res.exit_code == 2 and "expected NAME=VALUE" in res.output
