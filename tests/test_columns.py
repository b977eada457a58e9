"""Column mappings (simrunner.telemetry.columns; docs/telemetry.md "Logs with other columns or
units"): a team's own CSV read as the run log it means, and every mistake one line."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from simrunner.telemetry.columns import ColumnMap, ColumnMapError, Expression, column_map_from
from simrunner.telemetry.log import LogError, RunLog, log_from_columns, read_log, write_log

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "ros_log_columns.toml"
ROS_HEADER = ("header.stamp.sec,header.stamp.nanosec,header.frame_id,pose.position.x,pose.position.y,"
              "pose.orientation.x,pose.orientation.y,pose.orientation.z,pose.orientation.w,odom.speed,imu.gyro_z,"
              "servo,duty,motor_off")


def _write(tmp_path: Path, text: str, name: str = "log.csv") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _one_line(err: pytest.ExceptionInfo, start: str) -> str:
    text = str(err.value)
    assert text.startswith(start), text
    assert "\n" not in text
    return text


def _ros_pair(tmp_path: Path, n: int = 200) -> tuple[Path, Path]:
    """The same run as a native log file and as a ROS-style CSV (split stamps, quaternion of
    any norm, km/h, deg/s, servo and duty command units)."""
    rng = np.random.default_rng(3)
    stamp_ns = 1234 * 10**9 + np.cumsum(rng.integers(19_000_000, 21_000_000, n))
    yaw = rng.uniform(-3.1, 3.1, n)
    servo = rng.integers(-512, 513, n)
    duty = rng.integers(0, 101, n)
    native = log_from_columns({
        "t_s": [int(s) / 10**9 for s in stamp_ns], "x_m": rng.normal(0, 2, n), "y_m": rng.normal(0, 2, n),
        "yaw_rad": yaw, "speed_mps": rng.uniform(-0.5, 3, n), "yaw_rate_radps": rng.normal(0, 2, n),
        "speed_cmd_mps": duty / 100 * 3.1, "steer_cmd_rad": -servo / 512 * 0.40, "coast": rng.integers(0, 2, n)},
        "<native>")
    norm = rng.uniform(0.5, 2.0, n)
    rows = [ROS_HEADER]
    for k in range(n):
        sec, nsec = divmod(int(stamp_ns[k]), 10**9)
        q = (0.0, 0.0, norm[k] * math.sin(yaw[k] / 2), norm[k] * math.cos(yaw[k] / 2))
        cells = [sec, nsec, "map", native.x_m[k], native.y_m[k], *q, native.speed_mps[k] * 3.6,
                 math.degrees(native.yaw_rate_radps[k]), servo[k], duty[k], int(native.coast[k])]
        rows.append(",".join(c if isinstance(c, str) else repr(float(c)) if isinstance(c, float) else str(c)
                             for c in cells))
    ros = _write(tmp_path, "\n".join(rows) + "\n", "ros.csv")
    return write_log(native, tmp_path / "native.csv", float_format="%.17g"), ros


def _assert_close(a: RunLog, b: RunLog) -> None:
    assert a.names == b.names and len(a) == len(b)
    for name in a.names:
        assert a.column(name).dtype == b.column(name).dtype, name
        np.testing.assert_allclose(a.column(name), b.column(name), rtol=0, atol=1e-9, err_msg=name)


# -- mapped logs read as the native one ------------------------------------------------------
def test_ros_style_log_reads_as_the_native_log(tmp_path):
    native, ros = _ros_pair(tmp_path)
    mapped = read_log(ros, columns=column_map_from(EXAMPLE))
    _assert_close(mapped, read_log(native))
    assert mapped.source == str(ros)


@pytest.mark.parametrize("sep, decimal", [(";", "."), (";", ","), ("\t", ".")])
def test_a_spreadsheets_semicolon_or_tab_export_reads_as_the_comma_file(tmp_path, sep, decimal):
    """A European spreadsheet writes ``;`` between cells and decimal commas; others tabs. The
    same log reads the same, with and without a column mapping."""
    native, ros = _ros_pair(tmp_path)
    for path, cmap in ((native, None), (ros, column_map_from(EXAMPLE))):
        lines = path.read_text().splitlines(keepends=True)
        out = []
        for line in lines:
            if line.startswith("#"):
                out.append(line)
                continue
            cells = line.rstrip("\n").split(",")
            out.append(sep.join(c.replace(".", decimal) if re.fullmatch(r"[-+0-9.e]+", c) else c for c in cells) + "\n")
        other = _write(tmp_path, "".join(out), f"other_{path.name}")
        _assert_close(read_log(other, columns=cmap), read_log(path, columns=cmap))


def test_the_docs_example_is_the_example_file():
    docs = (ROOT / "docs" / "telemetry.md").read_text()
    section = docs[docs.index("## Logs with other columns or units"):]
    block = re.search(r"```toml\n(.*?)```", section, re.S).group(1)
    assert block == EXAMPLE.read_text()


def test_example_rules_know_their_lines():
    lines = EXAMPLE.read_text().splitlines()
    for rule in column_map_from(EXAMPLE).rules:
        assert lines[rule.origin.line - 1].startswith(f"{rule.target} = ")
        assert str(rule.origin) == f"{EXAMPLE}:{rule.origin.line}"


@pytest.mark.parametrize("target, unit, logged, expected", [
    ("t_s", "s", 2.5, 2.5), ("t_s", "ms", 2500, 2.5), ("t_s", "us", 2.5e6, 2.5), ("t_s", "ns", 2.5e9, 2.5),
    ("x_m", "m", 1.5, 1.5), ("x_m", "cm", 150, 1.5), ("x_m", "mm", 1500, 1.5),
    ("yaw_rad", "rad", 0.5, 0.5), ("yaw_rad", "deg", 90, math.pi / 2),
    ("speed_mps", "m/s", 2.0, 2.0), ("speed_mps", "km/h", 7.2, 2.0), ("speed_mps", "cm/s", 200, 2.0),
    ("speed_mps", "mm/s", 2000, 2.0), ("yaw_rate_radps", "rad/s", 1.0, 1.0), ("yaw_rate_radps", "deg/s", 180, math.pi),
])
def test_units(tmp_path, target, unit, logged, expected):
    p = _write(tmp_path, "t_s,v\n" + "".join(f"{k},{logged * (k + 1)!r}\n" for k in range(3)))
    log = read_log(p, columns=column_map_from(items=[f'{target}={{column = "v", unit = "{unit}"}}']))
    np.testing.assert_allclose(log.column(target), expected * np.arange(1, 4), rtol=1e-12)


def test_plain_names_dotted_names_backticks_and_expr_with_unit(tmp_path):
    p = _write(tmp_path, "%time,/odom/vx,pose.vy,stamp\n1,3.6,0,5\n2,0,7.2,6\n")
    cmap = column_map_from(items=["t_s=`%time` / 1e3", 'speed_mps={expr = "hypot(`/odom/vx`, pose.vy)", unit = "km/h"}',
                                  "x_m=stamp - 5"])
    log = read_log(p, columns=cmap)
    np.testing.assert_allclose(log.t_s, [0.001, 0.002])
    np.testing.assert_allclose(log.speed_mps, [1.0, 2.0])
    np.testing.assert_allclose(log.x_m, [0.0, 1.0])


def test_unmapped_columns_are_read_by_their_names_and_items_override_the_file(tmp_path):
    p = _write(tmp_path, "# nxpcup-sim run log, format 2\nt,speed_mps,v,lap,data_text,extra\n"
                         "0.0,1.0,3.6,0,\"a, b\",x\n0.1,2.0,7.2,1,c,y\n")
    cmap_file = _write(tmp_path, 'speed_mps = {column = "v", unit = "km/h"}\n', "map.toml")
    log = read_log(p, columns=column_map_from(cmap_file))
    assert log.names == ("t_s", "speed_mps", "lap", "data_text")
    np.testing.assert_allclose(log.speed_mps, [1.0, 2.0])
    assert log.data_text == ("a, b", "c") and log.lap.dtype == np.int64
    log = read_log(p, columns=column_map_from(cmap_file, ["speed_mps=v", "speed_mps=speed_mps * 10",
                                                          "data_text=extra"]))
    np.testing.assert_allclose(log.speed_mps, [10.0, 20.0])
    assert log.data_text == ("x", "y")


def test_an_empty_map_reads_as_no_map(tmp_path):
    native, _ = _ros_pair(tmp_path, 20)
    plain = read_log(native)
    for empty in (None, ColumnMap(), column_map_from()):
        _assert_close(read_log(native, columns=empty), plain)


def test_constant_and_flag_rules(tmp_path):
    p = _write(tmp_path, "t_s,mode\n0,3\n1,2\n2,3\n")
    log = read_log(p, columns=ColumnMap.from_toml_text('coast = "mode - 2"\nlap = 0\nframe = "t_s * 1"\n'))
    assert log.coast.tolist() == [True, False, True] and log.lap.tolist() == [0, 0, 0]
    assert log.frame.tolist() == [0, 1, 2]


# -- errors: one line, the file and line to fix --------------------------------------------
def test_missing_column_names_the_mapping_line(tmp_path):
    p = _write(tmp_path, "stamp_ns,x\n1,2\n")
    with pytest.raises(LogError) as err:
        read_log(p, columns=column_map_from(EXAMPLE))
    text = _one_line(err, f"{p}:1: mapping {EXAMPLE}:6 asks for column 'header.stamp.sec' (the file has: ")
    assert "stamp_ns, x" in text
    p = _write(tmp_path, "# nxpcup-sim run log, format 2\nt_s,x\n1,2\n")  # the header is line 2
    with pytest.raises(LogError) as err:
        read_log(p, columns=column_map_from(items=["x_m=pos_x"]))
    _one_line(err, f"{p}:2: mapping --column 'x_m=pos_x' asks for column 'pos_x' (the file has: t_s, x)")


def test_bad_unit_names_the_mapping_line(tmp_path):
    m = _write(tmp_path, '# speeds\n\nspeed_mps = {column = "v", unit = "kmh"}\n', "MAP.toml")
    with pytest.raises(ColumnMapError) as err:
        column_map_from(m)
    assert str(err.value) == f"{m}:3: unit 'kmh' for speed_mps: expected one of m/s, km/h, cm/s, mm/s"
    assert isinstance(err.value, LogError) and (err.value.path, err.value.line) == (str(m), 3)


def test_non_numeric_cell_names_the_log_line(tmp_path):
    p = _write(tmp_path, "# comment\nt,v\n0,1\n\n1,n/a\n")
    with pytest.raises(LogError) as err:
        read_log(p, columns=column_map_from(items=["speed_mps=v / 3.6"]))
    assert str(err.value) == f"{p}:5: column 'v': expected a number (got 'n/a')"


@pytest.mark.parametrize("text, line, what", [
    ('t_s = "t"\n[yaw_rad]\nquaternion = ["a", "b"]\n', 2, "yaw_rad: expected quaternion = [x, y, z, w]"),
    ('t_s = "t"\nx_m = {quaternion = ["a", "b", "c", "d"]}\n', 2, "x_m: expected quaternion"),
    ('x_m = {seconds = "s", nanoseconds = "ns"}\n', 1, "x_m: seconds and nanoseconds give a time"),
    ('t_s = {seconds = "s"}\n', 1, "t_s: expected one of column, expr, quaternion, or seconds with nanoseconds"),
    ('t_s = {column = "a", expr = "b"}\n', 1, "t_s: expected one of column"),
    ('t_s = {column = "a", units = "s"}\n', 1, "t_s: unknown key 'units'"),
    ('"yaw_rate_radps" = {quaternion = ["a", "b", "c", "d"], unit = "deg"}\n', 1, "unit goes with column or expr"),
    ('\n\ncoast = {column = "c", unit = "s"}\n', 3, "unit 's' for coast: expected no unit (coast is a 0/1 flag)"),
    ('x_m = {column = ""}\n', 1, "x_m: expected column names as non-empty strings"),
    ('x_m = {column = "x", unit = 3}\n', 1, "x_m: expected the unit as a string"),
    ('x_m = ["a"]\n', 1, "x_m: expected an expression string or a table"),
    ('x_m = true\n', 1, "x_m: expected an expression or a table"),
    ('data_text = "a + b"\n', 1, "data_text: expected a column name"),
    ('\nspeed = "v"\n', 2, "'speed' is not a run log column (did you mean speed_mps?)"),
    ('x_m = "a % 2"\n', 1, "x_m = 'a % 2': expected numbers, column names"),
    ('x_m = {expr = "a // 2", unit = "mm"}\n', 1, "x_m = 'a // 2': expected numbers"),
    ('x_m.column = "a"\nx_m.unit = "furlong"\n', 1, "unit 'furlong' for x_m"),
    ('t_s = "t"\nx_m = {column = "x" unit = "mm"}\n', 2, "expected a TOML column mapping"),
])
def test_mapping_file_errors(tmp_path, text, line, what):
    m = _write(tmp_path, text, "MAP.toml")
    with pytest.raises(ColumnMapError) as err:
        column_map_from(m)
    assert what in _one_line(err, f"{m}:{line}: ")


def test_missing_mapping_file(tmp_path):
    with pytest.raises(ColumnMapError) as err:
        column_map_from(tmp_path / "nope.toml")
    _one_line(err, f"{tmp_path / 'nope.toml'}: expected a readable TOML file")


@pytest.mark.parametrize("item, what", [
    ("t_s", "expected NAME=EXPR"),
    ("=v", "expected NAME=EXPR"),
    ("t_s={column=", "expected a TOML inline table after t_s="),
    ("speed=v", "'speed' is not a run log column"),
    ("speed_mps=v/", "speed_mps = 'v/': expected numbers"),
    ("speed_mps=open('x')", "(got a call of 'open')"),
    ("speed_mps=v.__class__()", "(got a call of something not a name)"),
    ("speed_mps=(1).real", "(got an attribute of something other than a name)"),
    ("speed_mps=v if v else 1", "(got if/else)"),
    ("speed_mps=v[0]", "(got an index [...])"),
    ("speed_mps=v > 1", "(got a comparison)"),
    ("speed_mps=lambda: 1", "(got a lambda)"),
    ("speed_mps='v'", "(got the constant 'v')"),
    ("speed_mps=`v", "(got an unmatched `)"),
    ("speed_mps=sqrt(v, 2)", "(sqrt takes 1 argument (got 2))"),
    ("speed_mps=min(v)", "(min takes at least 2 arguments (got 1))"),
    ("speed_mps=atan2(y=v, x=1)", "(got keyword or * arguments to atan2)"),
    ("speed_mps=" + "1" * 400, "(got a number too large for a float)"),
    ("speed_mps=" + "-" * 500 + "v", "nested operations"),
    ("speed_mps=" + "v+" * 600 + "v", "at most 1000"),
])
def test_command_line_item_errors(item, what):
    with pytest.raises(ColumnMapError) as err:
        column_map_from(items=["t_s=t", item])
    assert what in _one_line(err, f"--column {item!r}: ")
    assert (err.value.path, err.value.line) == ("--column", 2)


@pytest.mark.parametrize("rows, items, line, what", [
    ("0,0,0,0,1\n1,0,0,0,0\n", ['yaw_rad={quaternion = ["a", "b", "c", "d"]}'], 3,
     "yaw_rad (--column 'yaw_rad={quaternion = [\"a\", \"b\", \"c\", \"d\"]}'): quaternion a, b, c, d is all zero"),
    ("0,1,0,0,0\n1,0,1,0,0\n", ["x_m=a / b"], 2, "x_m = 'a / b' (--column 'x_m=a / b') gives inf: expected a finite"),
    ("0,1,0,0,0\n1,-1,0,0,0\n", ["x_m=sqrt(a)"], 3, "gives nan"),
    ("0,1,0,0,0\n1,0,0,0,0\n", ["t_s=a"], 3, "column 't_s': expected strictly increasing time (got 0.0 after 1.0)"),
    ("0,1,0,0,0\n1,0.5,0,0,0\n", ["coast=a"], 3, "column 'coast': expected 0 or 1"),
    ("0,1,0,0,0\n1,inf,0,0,0\n", ["x_m=a"], 3, "column 'a': expected a finite number (got 'inf')"),
])
def test_log_errors_after_mapping_name_the_log_line(tmp_path, rows, items, line, what):
    p = _write(tmp_path, "t,a,b,c,d\n" + rows)
    with pytest.raises(LogError) as err:
        read_log(p, columns=column_map_from(items=items))
    assert what in _one_line(err, f"{p}:{line}: ")


def test_no_time_column_and_a_repeated_source_column(tmp_path):
    p = _write(tmp_path, "a,b,b\n0,1,2\n")
    with pytest.raises(LogError) as err:
        read_log(p, columns=column_map_from(items=["x_m=a"]))
    _one_line(err, f"{p}:1: expected a time column t_s (or t) in the header, or a rule for t_s")
    with pytest.raises(LogError) as err:
        read_log(p, columns=column_map_from(items=["t_s=b"]))
    _one_line(err, f"{p}:1: mapping --column 't_s=b' asks for column 'b', which the header names 2 times")


# -- expressions: like numpy, or refused ---------------------------------------------------
_RNG = np.random.default_rng(11)
COLS = {"a": _RNG.normal(0, 3, 16), "b": _RNG.uniform(-1, 1, 16), "pose.x": _RNG.uniform(0, 5, 16),
        "%t": _RNG.normal(0, 100, 16)}
_LEAF_TEXT = {"a": "a", "b": "b", "pose.x": "pose.x", "%t": "`%t`"}


def _q(fn, *args):
    """``fn(*args)`` with numpy's rules for inf and nan, quietly (as Expression.evaluate)."""
    with np.errstate(all="ignore"):
        return fn(*args)


def _bin(op, x, y):
    return _q({"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.true_divide, "**": np.power}[op], x, y)


_numbers = st.floats(-1e3, 1e3, allow_nan=False).map(lambda v: (f"({v!r})", np.float64(v)))
_columns = st.sampled_from(sorted(COLS)).map(lambda n: (_LEAF_TEXT[n], COLS[n]))
_F1 = {"abs": np.abs, "sqrt": np.sqrt, "sin": np.sin, "cos": np.cos, "tan": np.tan, "radians": np.radians,
       "degrees": np.degrees}


def _extend(children):
    return st.one_of(
        st.tuples(st.sampled_from(["+", "-", "*", "/", "**"]), children, children).map(
            lambda t: (f"({t[1][0]} {t[0]} {t[2][0]})", _bin(t[0], t[1][1], t[2][1]))),
        children.map(lambda c: (f"(-{c[0]})", np.negative(c[1]))),
        st.tuples(st.sampled_from(sorted(_F1)), children).map(
            lambda t: (f"{t[0]}({t[1][0]})", _q(_F1[t[0]], t[1][1]))),
        st.tuples(st.sampled_from(["atan2", "hypot"]), children, children).map(
            lambda t: (f"{t[0]}({t[1][0]}, {t[2][0]})",
                       _q({"atan2": np.arctan2, "hypot": np.hypot}[t[0]], t[1][1], t[2][1]))),
        st.tuples(st.sampled_from(["min", "max"]), st.lists(children, min_size=2, max_size=3)).map(
            lambda t: (f"{t[0]}({', '.join(c[0] for c in t[1])})",
                       _reduce({"min": np.minimum, "max": np.maximum}[t[0]], [c[1] for c in t[1]]))),
    )


def _reduce(fn, values):
    out = values[0]
    for v in values[1:]:
        out = _q(fn, out, v)
    return out


def _safe_expressions():
    return st.recursive(st.one_of(_numbers, _columns), _extend, max_leaves=12)


@settings(max_examples=300, deadline=None)
@given(_safe_expressions())
def test_safe_expressions_evaluate_like_numpy(case):
    text, expected = case
    got = Expression.parse(text).evaluate(COLS)
    np.testing.assert_array_equal(np.broadcast_to(got, np.shape(expected)), expected)


_TOKENS = ["a", "b", "pose", ".", "x", "1", "2.5", "1e308", "0", "+", "-", "*", "/", "**", "%", "//", "(", ")",
           "[", "]", "{", "}", ",", ":", "=", "==", "<", "not", "and", "lambda", "if", "else", "for", "in",
           "sqrt", "min", "atan2", "__import__", "open", "'s'", '"', "`", "`%t`", "\\", "\n", " ", "@", "~",
           "yield", "await", "*", "j", "_q0", "True", "None", "..."]


@settings(max_examples=400, deadline=None)
@given(st.one_of(st.text(max_size=40), st.lists(st.sampled_from(_TOKENS), max_size=20).map("".join)))
def test_junk_expressions_are_refused_with_log_error(text):
    """Any text: an expression that evaluates (numpy's inf/nan) or one LogError line."""
    try:
        expression = Expression.parse(text)
    except LogError as err:
        assert "\n" not in str(err)
        return
    value = expression.evaluate({name: COLS["a"] for name in expression.columns})
    assert value.dtype == np.float64


@settings(max_examples=150, deadline=None)
@given(st.one_of(st.text(max_size=60),
                 st.lists(st.sampled_from(["t_s", "x_m", "coast", "data_text", "speed", " = ", "=", "{", "}",
                                           "[", "]", '"', "column", "unit", "km/h", "deg", "quaternion",
                                           "seconds", "nanoseconds", "expr", ",", "\n", "1", "a / b", "true"]),
                          max_size=25).map("".join)))
def test_junk_mappings_are_refused_with_log_error(text):
    for parse in (lambda: ColumnMap.from_toml_text(text, "MAP.toml"), lambda: ColumnMap.from_items([text])):
        try:
            cmap = parse()
        except ColumnMapError as err:
            assert "\n" not in str(err)
        else:
            assert isinstance(cmap, ColumnMap)


@settings(max_examples=80, deadline=None)
@given(st.lists(st.sampled_from(list("0123456789.,-eE abn\n\r#\"") + [ROS_HEADER, "header.stamp.sec", "servo"]),
                max_size=60).map("".join))
def test_mapped_read_never_crashes_on_junk(tmp_path_factory, junk):
    p = tmp_path_factory.mktemp("junk") / "j.csv"
    p.write_text(junk)
    try:
        log = read_log(p, columns=column_map_from(EXAMPLE))
    except LogError as err:
        assert str(err).startswith(f"{p}:") and "\n" not in str(err)
    else:
        assert isinstance(log, RunLog)


# -- the controller's own norm functions (--norms) -------------------------------------------
REAL_UNITS = ROOT / "examples" / "real_car_units.py"


def test_a_log_in_the_car_s_units_reads_through_the_controller_s_own_norm_functions(tmp_path):
    """The ROS-style log's servo and duty read through examples/real_car_units.py's
    spinner.configure(turn_norm=, speed_norm=), row by row: the native log, as the
    hand-written expressions of the example mapping give it."""
    from simrunner.run.norms import controller_norms

    native, ros = _ros_pair(tmp_path)
    items = ["steer_cmd_rad=turn_norm(duty, servo)", "speed_cmd_mps=speed_norm(duty, servo)"]
    mapped = read_log(ros, columns=column_map_from(EXAMPLE, items, controller_norms(REAL_UNITS)))
    _assert_close(mapped, read_log(native))


def test_norm_calls_parse_evaluate_and_say_what_is_missing(tmp_path):
    e = Expression.parse("2 * speed_norm(d, s / 2) + 1")
    assert e.norms == ("speed_norm",) and e.columns == ("d", "s")
    out = e.evaluate({"d": np.array([1.0, np.nan, 3.0]), "s": np.array([4.0, 5.0, 6.0])},
                     {"speed_norm": lambda v, a: v * 10 + a})
    assert out[0] == 2 * (10 + 2) + 1 and math.isnan(out[1]) and out[2] == 2 * (30 + 3) + 1  # empty cell: NaN
    with pytest.raises(ColumnMapError, match="speed_norm takes 2 arguments"):
        Expression.parse("speed_norm(d)")
    with pytest.raises(LogError, match=r"calls turn_norm: expected the controller's norm functions"):
        Expression.parse("turn_norm(d, s)").evaluate({"d": 1.0, "s": 1.0})
    with pytest.raises(ColumnMapError) as err:
        column_map_from(items=["steer_cmd_rad=turn_norm(duty, servo)"])
    _one_line(err, "--column 'steer_cmd_rad=turn_norm(duty, servo)': steer_cmd_rad calls turn_norm: expected "
                   "the controller whose norm functions it means: --norms CONTROLLER.py")
    with pytest.raises(ColumnMapError) as err:
        column_map_from(items=["x_m=a"], norms={"speed_norm": max, "turn_norm": max}, norms_from="--norms c.py")
    _one_line(err, "--norms c.py: no column rule calls speed_norm or turn_norm")


def _norm_read_error(tmp_path, norm_source: str, name: str, line: int) -> str:
    """The one-line error of reading a 3-row log whose speed command goes through a
    controller with ``speed_norm=norm_source`` (the controller's line 3)."""
    from simrunner.run.norms import controller_norms

    ctl = _write(tmp_path, f"def main(spinner):\n    spinner.configure(\n        speed_norm={norm_source})\n", name)
    p = _write(tmp_path, "t,duty,servo,x,y,yaw\n0,1,0,0,0,0\n0.1,2,0,0,0,0\n0.2,3,0,0,0,0\n")
    cmap = column_map_from(items=["speed_cmd_mps=speed_norm(duty, servo)", "steer_cmd_rad=servo"],
                           norms=controller_norms(ctl))
    with pytest.raises(LogError) as err:
        read_log(p, columns=cmap)
    return _one_line(err, f"{p}:{line}: speed_cmd_mps = 'speed_norm(duty, servo)' (--column ")


def test_a_norm_function_that_fails_names_the_log_line_and_its_own_line(tmp_path):
    text = _norm_read_error(tmp_path, "lambda v, a: 1.0 / (v - 2.0)", "ctl.py", 3)
    assert "speed_norm(speed=2.0, angle=0.0) raised ZeroDivisionError: float division by zero at " in text
    assert text.endswith("ctl.py:3")


@pytest.mark.parametrize("source, what", [
    ("def main(spinner):\n    return\n", None),  # never configures: m/s and radians
    ("def main(spinner):\n    spinner.get_image()\n", "uses spinner.get_image before spinner.configure"),
    ("def main(spinner):\n    x = 1 / 0\n", "failed before configuring its norms: ZeroDivisionError"),
    ("from simrunner.run.spinner import Spinner\n\ndef main(spinner):\n    Spinner(turn_norm=abs)\n",
     "main builds Spinner(...) itself"),
])
def test_controller_norms_of_odd_controllers(tmp_path, source, what):
    from simrunner.errors import ControllerFileError
    from simrunner.run.norms import controller_norms

    ctl = _write(tmp_path, source, "ctl.py")
    if what is None:
        norms = controller_norms(ctl)
        assert norms["speed_norm"](1.5, 0.2) == 1.5 and norms["turn_norm"](1.5, 0.2) == 0.2
        return
    with pytest.raises(ControllerFileError, match=re.escape(what)) as err:
        controller_norms(ctl)
    assert "\n" not in str(err.value) and str(err.value).startswith(str(ctl))
    with pytest.raises(ControllerFileError, match="expected a Python controller"):
        controller_norms(_write(tmp_path, "int main(void) { return 0; }\n", "ctl.c"))


def test_controller_norms_follow_every_configure_call_and_refuse_what_is_no_function(tmp_path):
    """configure() twice keeps both norms, as the Spinner does; main stops at its next use
    of the Spinner; a norm that is no function, or returns no number, is one line naming it."""
    from simrunner.errors import ControllerFileError
    from simrunner.run.norms import controller_norms

    ctl = _write(tmp_path, "def main(spinner):\n    spinner.configure(turn_norm=lambda v, a: -a)\n"
                           "    spinner.configure(speed_norm=lambda v, a: v / 100)\n    spinner.get_image()\n"
                           "    raise RuntimeError('never here')\n", "twice.py")
    norms = controller_norms(ctl)
    assert norms["speed_norm"](50.0, 1.0) == 0.5 and norms["turn_norm"](50.0, 1.0) == -1.0
    bad = _write(tmp_path, "def main(spinner):\n    spinner.configure(speed_norm=3.1)\n", "bad.py")
    with pytest.raises(ControllerFileError, match=r"configure\(speed_norm=3.1\): expected a function"):
        controller_norms(bad)
    text = _norm_read_error(tmp_path, "lambda v, a: None", "none.py", 2)
    assert "speed_norm(speed=1.0, angle=0.0) returned None: expected a number (defined at " in text
    assert text.endswith("none.py:3)")


def test_a_partial_map_leaves_out_a_missing_sensor_but_not_a_misnamed_column(tmp_path):
    """Several logs under one map (ColumnMap.partial): a log without the camera's columns
    reads without a pose; a log with two of them and a misnamed third is refused, naming
    the third, as a single log is."""
    import dataclasses

    m = dataclasses.replace(column_map_from(items=["t_s=stamp", "x_m=cam_x", "y_m=cam_y", "yaw_rad=cam_yaw",
                                                   "speed_mps=enc_v", "speed_cmd_mps=v", "steer_cmd_rad=d"]),
                            partial=True)
    enc = _write(tmp_path, "stamp,enc_v,v,d\n0,1,1,0\n0.1,1,1,0\n", "enc.csv")
    assert read_log(enc, columns=m).names == ("t_s", "speed_mps", "speed_cmd_mps", "steer_cmd_rad")
    typo = _write(tmp_path, "stamp,cam_x,cam_y,cam_heading,enc_v,v,d\n0,0,0,0,1,1,0\n0.1,0,0,0,1,1,0\n", "typo.csv")
    with pytest.raises(LogError) as err:
        read_log(typo, columns=m)
    assert "asks for column 'cam_yaw'" in _one_line(err, f"{typo}:1: mapping --column 'yaw_rad=cam_yaw'")


def test_a_misspelt_column_is_named_not_silently_ignored(tmp_path):
    """Unknown columns are ignored, but one that looks like a schema column misspelt is named
    (issue 50: a 'spéed' column was silently dropped); the CLI prints it as one warning line."""
    import warnings

    from click.testing import CliRunner

    from simrunner.cli import main as cli
    from simrunner.telemetry.log import LogWarning, read_log

    path = tmp_path / "log.csv"
    path.write_text("t_s,x_m,y_m,spéed_mps,battery_v\n0,0,0,1,7.2\n0.1,0.1,0,1,7.2\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_log(path)
    texts = [str(w.message) for w in caught if issubclass(w.category, LogWarning)]
    assert log.speed_mps is None
    assert texts == [f"{path}:1: column 'spéed_mps' is not read: did you mean 'speed_mps'? (columns are read "
                     "by their exact names, docs/telemetry.md)"]
    res = CliRunner().invoke(cli, ["plot", str(path), "-o", str(tmp_path / "p.png")])
    assert res.exit_code == 0 and "simrunner: warning: " in res.output and "LogWarning" not in res.output


def test_controller_norms_survive_os_exit_and_a_loop_after_configure(tmp_path):
    """Issue 50 (fault injection): os._exit ended gap --norms with status 0 and nothing
    written; a loop after configure() hung with no limit."""
    from simrunner.errors import ControllerFileError
    from simrunner.run.norms import controller_norms

    ctl = tmp_path / "exits.py"
    ctl.write_text("import os\ndef main(s):\n    os._exit(3)\n")
    with pytest.raises(ControllerFileError, match=r"exits.py: main\(spinner\) called os._exit\(3\) before"):
        controller_norms(ctl)
    ctl = tmp_path / "loops.py"
    ctl.write_text("def main(s):\n    s.configure(speed_norm=lambda v, a: v / 100)\n    while True:\n        pass\n")
    norms = controller_norms(ctl, wall_limit_s=0.5)
    assert norms["speed_norm"](50.0, 0.0) == 0.5
    ctl = tmp_path / "spins.py"
    ctl.write_text("def main(s):\n    while True:\n        pass\n")
    with pytest.raises(ControllerFileError, match=r"ran 0.5 s without configuring its norms"):
        controller_norms(ctl, wall_limit_s=0.5)


def test_a_missing_or_short_column_is_named_at_the_header_line_of_a_file_with_comments(tmp_path):
    """simrunner's own logs start with a '# nxpcup-sim run log' line: a misspelt
    speed_cmd_mps was warned at line 2 (the header) but refused at line 1 (the comment)."""
    path = tmp_path / "run.csv"
    path.write_text("# nxpcup-sim run log, format 2\n# team notes\nt_s,sped_cmd_mps,steer_cmd_rad\n"
                    "0.0,1.0,0.0\n0.1,1.0,0.0\n")
    with pytest.warns(UserWarning, match=r"run.csv:3: column 'sped_cmd_mps'"):
        log = read_log(path)
    with pytest.raises(LogError, match=r"run.csv:3: expected columns t_s, speed_cmd_mps"):
        log.require("t_s", "speed_cmd_mps")
    with pytest.raises(LogError, match=r"run.csv:5: expected at least 3 rows"):
        log.require("t_s", min_rows=3)
