"""Column mappings: read a team's own log (other column names, other units) as a RunLog.

A :class:`ColumnMap` says how each column of the run log schema (docs/telemetry.md) is
computed from the columns of a CSV a team logged. One rule per schema column, written in a
small TOML file (keys: schema columns) or as command-line items ``NAME=EXPR``::

    t_s = {seconds = "header.stamp.sec", nanoseconds = "header.stamp.nanosec"}
    x_m = {column = "pose.x", unit = "mm"}
    yaw_rad = {quaternion = ["qx", "qy", "qz", "qw"]}
    speed_mps = {column = "v", unit = "km/h"}
    steer_cmd_rad = "-servo / 512 * 0.40"      # the car's turn_norm

:func:`simrunner.telemetry.log.read_log` applies it: ``read_log(path, columns=column_map_from(
"map.toml", ["speed_mps=v/3.6"]))``. Schema columns the map has no rule for are read by
their own names (format 2 or 1), as without a map.

Every rule compiles to one :class:`Expression` (a unit is a factor, a quaternion is
``atan2``, split stamps are a sum), parsed with :mod:`ast` and evaluated on numpy arrays by
walking a tree of the allowed operations; nothing reaches ``eval``. Errors are
:class:`ColumnMapError` (a :class:`~simrunner.telemetry.log.LogError`) naming the mapping's file
and line, or the command-line item; errors in the log name the log's file and line.
"""
from __future__ import annotations

import ast
import difflib
import math
import re
import tomllib
import warnings
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from simrunner.telemetry.log import COLUMN_NAMES, COLUMNS, FORMAT1_NAMES, LogError, read_log
from simrunner.telemetry.sparse import is_empty_cell

_BY_NAME = {c.name: c for c in COLUMNS}

# -- units ---------------------------------------------------------------------------------
# schema unit -> {unit a team may log in: how to turn a value ``{}`` of it into the schema unit}
UNITS: dict[str, dict[str, str]] = {
    "s": {"s": "{}", "ms": "{} / 1e3", "us": "{} / 1e6", "ns": "{} / 1e9"},
    "m": {"m": "{}", "cm": "{} / 100", "mm": "{} / 1000"},
    "rad": {"rad": "{}", "deg": "radians({})"},
    "m/s": {"m/s": "{}", "km/h": "{} / 3.6", "cm/s": "{} / 100", "mm/s": "{} / 1000"},
    "rad/s": {"rad/s": "{}", "deg/s": "radians({})"},
}
_NO_UNIT = {"int": "a whole number", "flag": "a 0/1 flag", "text": "text"}

# -- expressions ---------------------------------------------------------------------------
MAX_EXPRESSION_CHARS = 1000
MAX_DEPTH = 200  # nested operations in one expression
_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
_REFUSED_OPERATORS = {ast.Mod: "%", ast.FloorDiv: "//", ast.MatMult: "@", ast.LShift: "<<",
                      ast.RShift: ">>", ast.BitOr: "|", ast.BitXor: "^", ast.BitAnd: "&",
                      ast.Not: "not", ast.Invert: "~"}
_UFUNCS = {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.true_divide, "**": np.power}
# name -> (number of arguments, -2 = two or more; numpy function, element-wise)
FUNCTIONS: dict[str, tuple[int, Callable]] = {
    "abs": (1, np.abs), "sqrt": (1, np.sqrt), "sin": (1, np.sin), "cos": (1, np.cos), "tan": (1, np.tan),
    "atan2": (2, np.arctan2), "hypot": (2, np.hypot), "radians": (1, np.radians), "degrees": (1, np.degrees),
    "min": (-2, np.minimum), "max": (-2, np.maximum),
}
# the columns every log needs: a partial map (ColumnMap.partial) never skips their rules
NEEDED = ("t_s", "speed_cmd_mps", "steer_cmd_rad")
POSE_COLUMNS = ("x_m", "y_m", "yaw_rad")  # one sensor: a partial map leaves them out together
# the controller's own norm functions (simrunner.run.spinner), given with --norms CONTROLLER.py:
# name(speed, angle) in the controller's units -> m/s or rad, called row by row
NORM_FUNCTIONS = ("speed_norm", "turn_norm")
ALLOWED = ("numbers, column names (other names in backticks: `%time`), + - * / **, unary minus, "
           f"parentheses, {', '.join(FUNCTIONS)} and the controller's {' and '.join(NORM_FUNCTIONS)}")
_NODE_WORDS = {ast.Compare: "a comparison", ast.BoolOp: "and/or", ast.Subscript: "an index [...]",
               ast.Lambda: "a lambda", ast.IfExp: "if/else", ast.List: "a list", ast.Tuple: "a tuple",
               ast.Dict: "a dict", ast.Set: "a set", ast.JoinedStr: "an f-string", ast.NamedExpr: ":=",
               ast.ListComp: "a comprehension", ast.GeneratorExp: "a comprehension",
               ast.SetComp: "a comprehension", ast.DictComp: "a comprehension", ast.Starred: "*",
               ast.Await: "await", ast.Yield: "yield", ast.YieldFrom: "yield", ast.Slice: "a slice"}


@dataclass(frozen=True)
class Origin:
    """Where a rule was written: ``path:line`` of a mapping file, or a command-line item
    (``path`` ``"--column"``, ``line`` its position among the items, ``item`` its text)."""

    path: str
    line: int
    item: str = ""

    def __str__(self) -> str:
        if self.item:
            return f"--column {self.item!r}"
        return f"{self.path}:{self.line}" if self.line else self.path  # (line 0: the file as a whole)


class ColumnMapError(LogError):
    """A column mapping is malformed. ``str(err)`` is ``MAP.toml:LINE: what was expected``
    (or ``--column 'NAME=EXPR': ...`` for a command-line item)."""

    def __init__(self, origin: Origin, message: str):
        super().__init__(origin.path, origin.line, message)
        self.origin = origin
        # one line, whatever the user typed (a line break inside an item or a name)
        self.args = (f"{origin}: {message}".replace("\r", "\\r").replace("\n", "\\n"),)

    def __str__(self) -> str:
        return self.args[0]


_EXPRESSION = Origin("<expression>", 0)


@dataclass(frozen=True)
class Expression:
    """An arithmetic expression over a log's columns, checked when parsed (:meth:`parse`).

    ``tree`` is nested tuples: ``("num", value)``, ``("col", name)``, ``("neg", a)``,
    ``(op, a, b)`` for op in ``+ - * / **``, ``("call", function, (args...))``.
    """

    text: str
    tree: tuple
    columns: tuple[str, ...]  # the columns it reads, in order of first use

    @classmethod
    def parse(cls, text: str, origin: Origin = _EXPRESSION, what: str = "expression ") -> "Expression":
        """Parse ``text``; raise :class:`ColumnMapError` (``origin: what'text': expected ...``)
        for anything but :data:`ALLOWED`."""

        def refuse(detail: str) -> ColumnMapError:
            return ColumnMapError(origin, f"{what}{text!r}: expected {ALLOWED} ({detail})")

        if not isinstance(text, str):
            raise ColumnMapError(origin, f"{what}{text!r}: expected an expression string")
        if len(text) > MAX_EXPRESSION_CHARS:
            raise refuse(f"got {len(text)} characters, at most {MAX_EXPRESSION_CHARS}")
        if text.count("`") % 2:
            raise refuse("got an unmatched `")
        prefix = "_q"
        while prefix in text:
            prefix += "_"
        quoted: dict[str, str] = {}

        def placeholder(m: re.Match) -> str:
            quoted[f"{prefix}{len(quoted)}"] = m.group(1)
            return f" {prefix}{len(quoted) - 1} "

        source = re.sub(r"`([^`]*)`", placeholder, text).strip()
        if any(not name for name in quoted.values()):
            raise refuse("got an empty column name ``")
        try:
            with warnings.catch_warnings():  # "invalid decimal literal" and the like: refused below
                warnings.simplefilter("ignore", SyntaxWarning)
                body = ast.parse(source, mode="eval").body
        except (SyntaxError, ValueError, MemoryError, RecursionError) as exc:
            detail = getattr(exc, "msg", None) or str(exc) or type(exc).__name__
            raise refuse(" ".join(str(detail).split())) from None
        names: list[str] = []

        def convert(node: ast.AST, depth: int) -> tuple:
            if depth > MAX_DEPTH:
                raise refuse(f"got more than {MAX_DEPTH} nested operations")
            if isinstance(node, ast.Constant):
                v = node.value
                if isinstance(v, bool) or not isinstance(v, (int, float)):
                    raise refuse(f"got the constant {v!r}")
                try:
                    return ("num", float(v))
                except OverflowError:
                    raise refuse("got a number too large for a float") from None
            if isinstance(node, (ast.Name, ast.Attribute)):
                parts = []
                while isinstance(node, ast.Attribute):  # a dotted column name: pose.position.x
                    parts.append(node.attr)
                    node = node.value
                if not isinstance(node, ast.Name):
                    raise refuse("got an attribute of something other than a name")
                parts.append(quoted.get(node.id, node.id))
                name = ".".join(reversed(parts))
                if name not in names:
                    names.append(name)
                return ("col", name)
            if isinstance(node, ast.BinOp):
                op = _BINARY.get(type(node.op))
                if op is None:
                    raise refuse(f"got the operator {_operator(node.op)}")
                return (op, convert(node.left, depth + 1), convert(node.right, depth + 1))
            if isinstance(node, ast.UnaryOp):
                if isinstance(node.op, ast.USub):
                    return ("neg", convert(node.operand, depth + 1))
                if isinstance(node.op, ast.UAdd):
                    return convert(node.operand, depth + 1)
                raise refuse(f"got the operator {_operator(node.op)}")
            if isinstance(node, ast.Call):
                fname = node.func.id if isinstance(node.func, ast.Name) else None
                if fname in NORM_FUNCTIONS:
                    if node.keywords or len(node.args) != 2 or any(isinstance(a, ast.Starred) for a in node.args):
                        raise refuse(f"{fname} takes 2 arguments, speed and angle in the controller's units")
                    return ("norm", fname, tuple(convert(a, depth + 1) for a in node.args))
                if fname not in FUNCTIONS:
                    raise refuse(f"got a call of {fname!r}" if fname else "got a call of something not a name")
                if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
                    raise refuse(f"got keyword or * arguments to {fname}")
                arity = FUNCTIONS[fname][0]
                if (arity > 0 and len(node.args) != arity) or (arity < 0 and len(node.args) < -arity):
                    want = f"{arity}" if arity > 0 else f"at least {-arity}"
                    raise refuse(f"{fname} takes {want} argument{'s' if arity != 1 else ''} "
                                 f"(got {len(node.args)})")
                return ("call", fname, tuple(convert(a, depth + 1) for a in node.args))
            raise refuse(f"got {_NODE_WORDS.get(type(node), 'Python ' + type(node).__name__)}")

        tree = convert(body, 0)
        return cls(text, tree, tuple(names))

    @property
    def norms(self) -> tuple[str, ...]:
        """The controller's norm functions it calls (:data:`NORM_FUNCTIONS`)."""
        found: list[str] = []

        def walk(node: tuple) -> None:
            if node[0] == "norm" and node[1] not in found:
                found.append(node[1])
            for child in node[1:]:
                if isinstance(child, tuple):
                    for c in (child if child and isinstance(child[0], tuple) else (child,)):
                        walk(c)

        walk(self.tree)
        return tuple(found)

    def evaluate(self, columns: Mapping[str, np.ndarray | float],
                 norms: Mapping[str, Callable[[float, float], float]] | None = None) -> np.ndarray:
        """The value, float64, broadcast over the columns' shape (0-d without columns);
        numpy's rules for inf and nan (no warnings). Raises :class:`LogError` if ``columns``
        lacks one this expression reads, or ``norms`` a norm function it calls; a norm
        function that raises or returns no number raises :class:`NormFault` (its row)."""
        missing = [n for n in self.columns if n not in columns]
        if missing:
            raise LogError("<expression>", 0, f"expression {self.text!r} reads column {missing[0]!r} "
                                              f"(got columns: {', '.join(map(repr, columns)) or 'none'})")
        absent = [n for n in self.norms if not norms or n not in norms]
        if absent:
            raise LogError("<expression>", 0, f"expression {self.text!r} calls {absent[0]}: expected the "
                                              "controller's norm functions (simrunner gap --norms CONTROLLER.py)")
        values = {n: np.asarray(columns[n], dtype=float) for n in self.columns}
        with np.errstate(all="ignore"):
            return np.asarray(_evaluate(self.tree, values, norms or {}), dtype=float)


def _operator(op: ast.AST) -> str:
    return _REFUSED_OPERATORS.get(type(op), type(op).__name__)


class NormFault(Exception):
    """A controller's norm function failed at ``row`` (index into the evaluated arrays)."""

    def __init__(self, row: int, message: str):
        super().__init__(message)
        self.row = row
        self.message = message


def _call_norm(name: str, fn: Callable[[float, float], float], speed, angle) -> np.ndarray:
    """``fn(speed, angle)`` row by row (NaN where an argument is NaN: an empty cell)."""
    a, b = np.broadcast_arrays(np.asarray(speed, dtype=float), np.asarray(angle, dtype=float))
    out = np.full(a.shape, np.nan)
    flat_a, flat_b, flat = a.reshape(-1), b.reshape(-1), out.reshape(-1)
    for i in np.flatnonzero(np.isfinite(flat_a) & np.isfinite(flat_b)):
        call = f"{name}(speed={float(flat_a[i])!r}, angle={float(flat_b[i])!r})"
        try:
            v = fn(float(flat_a[i]), float(flat_b[i]))
        except Exception as exc:  # noqa: BLE001 - the user's function: any fault is reported
            tb = exc.__traceback__
            while tb is not None and tb.tb_next is not None:
                tb = tb.tb_next
            where = f" at {tb.tb_frame.f_code.co_filename}:{tb.tb_lineno}" if tb is not None else ""
            raise NormFault(int(i), f"{call} raised {type(exc).__name__}: {exc}{where}") from None
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            code = getattr(fn, "__code__", None)
            where = f" (defined at {code.co_filename}:{code.co_firstlineno})" if code is not None else ""
            raise NormFault(int(i), f"{call} returned {v!r}: expected a number{where}")
        flat[i] = float(v)
    return out


def _evaluate(node: tuple, values: Mapping[str, np.ndarray], norms: Mapping[str, Callable]):
    kind = node[0]
    if kind == "num":
        return np.float64(node[1])
    if kind == "col":
        return values[node[1]]
    if kind == "neg":
        return np.negative(_evaluate(node[1], values, norms))
    if kind == "norm":
        speed, angle = (_evaluate(a, values, norms) for a in node[2])
        return _call_norm(node[1], norms[node[1]], speed, angle)
    if kind == "call":
        arity, fn = FUNCTIONS[node[1]]
        args = [_evaluate(a, values, norms) for a in node[2]]
        if arity < 0:  # min/max: element-wise over all arguments
            out = args[0]
            for a in args[1:]:
                out = fn(out, a)
            return out
        return fn(*args)
    return _UFUNCS[kind](_evaluate(node[1], values, norms), _evaluate(node[2], values, norms))


def _quote(name: str) -> str:
    return f"`{name}`"


# -- rules and maps ------------------------------------------------------------------------
@dataclass(frozen=True)
class ColumnRule:
    """How one schema column is computed: ``expression`` over the log's columns gives it in
    the schema's unit. ``data_text`` is copied from the one column its expression names.
    ``nonzero``: columns that must not all be zero in a row (a quaternion's components)."""

    target: str
    expression: Expression
    origin: Origin
    nonzero: tuple[str, ...] = ()

    @property
    def sources(self) -> tuple[str, ...]:
        return self.expression.columns


_TABLE_KEYS = ("column", "expr", "unit", "quaternion", "seconds", "nanoseconds")


def _rule(target: str, value: object, origin: Origin) -> ColumnRule:
    """One rule from a TOML value (see the module docstring); raises :class:`ColumnMapError`."""
    column = _BY_NAME.get(target)
    if column is None:
        hint = f" (did you mean {FORMAT1_NAMES[target]}?)" if target in FORMAT1_NAMES else ""
        raise ColumnMapError(origin, f"{target!r} is not a run log column{hint}: expected one of "
                                     f"{', '.join(COLUMN_NAMES)}")
    what = f"{target} = "
    unit, nonzero = None, ()
    if isinstance(value, bool) or (isinstance(value, float) and not math.isfinite(value)):
        raise ColumnMapError(origin, f"{target}: expected an expression or a table (got {value!r})")
    if isinstance(value, (int, float)):
        text = repr(value)
    elif isinstance(value, str):
        text = value
    elif isinstance(value, dict):
        unknown = [k for k in value if k not in _TABLE_KEYS]
        if unknown:
            raise ColumnMapError(origin, f"{target}: unknown key {unknown[0]!r}: expected "
                                         f"{', '.join(_TABLE_KEYS)}")
        kinds = [k for k in ("column", "expr", "quaternion", "seconds") if k in value]
        if len(kinds) != 1 or ("nanoseconds" in value) != ("seconds" in value):
            raise ColumnMapError(origin, f"{target}: expected one of column, expr, quaternion, or seconds with "
                                         f"nanoseconds (got {', '.join(value) or 'an empty table'})")
        kind = kinds[0]
        if "unit" in value and kind not in ("column", "expr"):
            raise ColumnMapError(origin, f"{target}: unit goes with column or expr (a quaternion gives "
                                         f"radians, split stamps give seconds)")
        strings = [value[k] for k in ("column", "seconds", "nanoseconds") if k in value]
        strings += value.get("quaternion", []) if isinstance(value.get("quaternion"), list) else []
        for s in strings:
            if not isinstance(s, str) or not s or "`" in s:
                raise ColumnMapError(origin, f"{target}: expected column names as non-empty strings without ` "
                                             f"(got {s!r})")
        if kind == "column":
            text = _quote(value["column"])
        elif kind == "expr":
            text = Expression.parse(value["expr"], origin, what).text  # errors quote the text as written
        elif kind == "quaternion":
            q = value["quaternion"]
            if target != "yaw_rad" or not isinstance(q, list) or len(q) != 4:
                raise ColumnMapError(origin, f"{target}: expected quaternion = [x, y, z, w] (four column "
                                             f"names) for yaw_rad")
            x, y, z, w = map(_quote, q)
            text = f"atan2(2 * ({w} * {z} + {x} * {y}), {w} ** 2 + {x} ** 2 - {y} ** 2 - {z} ** 2)"
            nonzero = tuple(q)
        else:
            if column.unit != "s":
                raise ColumnMapError(origin, f"{target}: seconds and nanoseconds give a time (t_s)")
            text = f"{_quote(value['seconds'])} + {_quote(value['nanoseconds'])} / 1e9"
        unit = value.get("unit")
        if unit is not None:
            forms = UNITS.get(column.unit)
            if not isinstance(unit, str):
                raise ColumnMapError(origin, f"{target}: expected the unit as a string (got {unit!r})")
            if forms is None:
                raise ColumnMapError(origin, f"unit {unit!r} for {target}: expected no unit ({target} is "
                                             f"{_NO_UNIT[column.kind]})")
            if unit not in forms:
                raise ColumnMapError(origin, f"unit {unit!r} for {target}: expected one of {', '.join(forms)}")
            text = forms[unit].format(text if kind == "column" else f"({text})")
    else:
        raise ColumnMapError(origin, f"{target}: expected an expression string or a table such as "
                                     f"{{column = \"v\", unit = \"km/h\"}} (got {type(value).__name__})")
    expression = Expression.parse(text, origin, what)
    if column.kind == "text" and expression.tree[0] != "col":
        raise ColumnMapError(origin, f"{target}: expected a column name (text is copied, not computed)")
    return ColumnRule(target, expression, origin, nonzero)


def _key_line(text: str, key: str) -> int:
    """The line of ``key`` in TOML ``text`` (``key =``, ``key.sub =``, ``[key]``; quoted or
    not; 0 if not found): tomllib gives no positions."""
    k = re.escape(key)
    m = re.search(rf"""^[ \t]*(?:\[[ \t]*)?(?:{k}|"{k}"|'{k}')[ \t]*[=.\]]""", text, re.M)
    return text.count("\n", 0, m.start()) + 1 if m else 0


def _toml_error_line(exc: tomllib.TOMLDecodeError) -> tuple[int, str]:
    m = re.search(r"\s*\(at line (\d+), column \d+\)", str(exc))
    return (int(m.group(1)), str(exc)[:m.start()]) if m else (getattr(exc, "lineno", 0), str(exc))


def _listing(names: Sequence[str], limit: int = 20) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f", ... ({len(names) - limit} more)" if len(names) > limit else "")


@dataclass(frozen=True)
class ColumnMap:
    """Rules for some schema columns, one each, in schema order (see the module docstring).
    An empty map reads a log exactly as no map."""

    rules: tuple[ColumnRule, ...] = ()
    # the controller's norm functions the rules may call (controller_norms); not compared
    norms: Mapping[str, Callable[[float, float], float]] | None = field(default=None, compare=False)
    # one map for several logs of one car with other sensors (simrunner gap a.csv b.csv): a
    # rule for a sensor column (not time, not a command) whose source columns a log lacks
    # leaves that column out of that log (the caller checks that some log had them)
    partial: bool = field(default=False, compare=False)

    @classmethod
    def from_rules(cls, rules: Iterable[ColumnRule]) -> "ColumnMap":
        """The map of ``rules``; a later rule for a column replaces an earlier one."""
        by_target = {r.target: r for r in rules}
        return cls(tuple(by_target[n] for n in COLUMN_NAMES if n in by_target))

    @classmethod
    def from_dict(cls, values: Mapping[str, object], path: str = "<mapping>",
                  line_of: Callable[[str], int] = lambda key: 0) -> "ColumnMap":
        """The map of ``{schema column: TOML value}`` (``line_of(key)`` for messages)."""
        return cls.from_rules(_rule(k, v, Origin(str(path), line_of(k))) for k, v in values.items())

    @classmethod
    def from_toml_text(cls, text: str, path: str = "<mapping>") -> "ColumnMap":
        """The map written in TOML ``text`` (``path`` names it in messages)."""
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            line, message = _toml_error_line(exc)
            raise ColumnMapError(Origin(str(path), line),
                                 f"expected a TOML column mapping ({message})") from None
        return cls.from_dict(data, str(path), lambda key: _key_line(text, key))

    @classmethod
    def from_toml(cls, path: str | Path) -> "ColumnMap":
        """The map in the TOML file ``path``."""
        try:
            text = Path(path).read_text(encoding="utf-8-sig")
        except OSError as exc:
            raise ColumnMapError(Origin(str(path), 0),
                                 f"expected a readable TOML file ({exc.strerror})") from None
        except UnicodeDecodeError:
            raise ColumnMapError(Origin(str(path), 1), "expected a UTF-8 text (TOML) file") from None
        return cls.from_toml_text(text, str(path))

    @classmethod
    def from_items(cls, items: Iterable[str]) -> "ColumnMap":
        """The map of command-line items ``NAME=EXPR`` or ``NAME={TOML inline table}``; a
        later item for a column replaces an earlier one."""
        rules = []
        for k, item in enumerate(items, 1):
            origin = Origin("--column", k, item)
            name, sep, rhs = item.partition("=")
            name, rhs = name.strip(), rhs.strip()
            if not sep or not name or not rhs:
                raise ColumnMapError(origin, "expected NAME=EXPR (e.g. speed_mps=v/3.6 or "
                                             "t_s={column=\"stamp\", unit=\"ns\"})")
            value: object = rhs
            if rhs.startswith("{"):
                try:
                    value = tomllib.loads(f"value = {rhs}")["value"]
                except tomllib.TOMLDecodeError as exc:
                    raise ColumnMapError(origin, f"expected a TOML inline table after {name}= "
                                                 f"({_toml_error_line(exc)[1]})") from None
            rules.append(_rule(name, value, origin))
        return cls.from_rules(rules)

    @property
    def targets(self) -> tuple[str, ...]:
        """The schema columns this map has rules for."""
        return tuple(r.target for r in self.rules)

    def merged(self, override: "ColumnMap") -> "ColumnMap":
        """This map with ``override``'s rules replacing or adding to its own."""
        return ColumnMap.from_rules(self.rules + override.rules)

    # -- reading a log (used by simrunner.telemetry.log.read_log) --------------------------------
    def columns_to_read(self, header: Sequence[str], header_line: int, source: str) -> dict[str, int]:
        """``{name: index}`` of the header's columns to read: those the rules use, then the
        schema-named ones the map has no rule for. Raises :class:`LogError`
        (``source:header_line: ...``) for a column the file lacks."""
        index: dict[str, int] = {}
        for i, h in enumerate(header):
            index.setdefault(h, i)
        wanted: dict[str, int] = {}
        skipped = set(self.absent_sensors(index)) if self.partial else set()
        for rule in self.rules:
            if rule.target in skipped:
                continue  # this log has not that sensor
            for name in rule.sources:
                if name not in index:
                    close = difflib.get_close_matches(name, list(index), n=1)
                    hint = f"; did you mean {close[0]!r}?" if close else ""
                    raise LogError(source, header_line, f"mapping {rule.origin} asks for column {name!r} "
                                                        f"(the file has: {_listing(list(header))}{hint})")
                if header.count(name) > 1:
                    raise LogError(source, header_line, f"mapping {rule.origin} asks for column {name!r}, "
                                                        f"which the header names {header.count(name)} times")
                wanted[name] = index[name]
        passthrough = self._passthrough(index)
        if "t_s" not in self.targets and "t_s" not in passthrough.values():
            raise LogError(source, header_line, "expected a time column t_s (or t) in the header, or a rule "
                                                "for t_s in the column mapping")
        for name in passthrough:
            wanted.setdefault(name, index[name])
        return wanted

    def absent_sensors(self, header: Iterable[str]) -> tuple[str, ...]:
        """The sensor columns a partial map leaves out of a log with ``header``: those whose
        rule finds none of its source columns there, the pose's three only together (a log
        with some of a sensor's columns, or of the pose's, lacks the others by mistake: the
        read names them)."""
        have = set(header)
        gone = [r.target for r in self.rules
                if r.target not in NEEDED and r.sources and not any(n in have for n in r.sources)]
        pose = [r.target for r in self.rules if r.target in POSE_COLUMNS]
        if any(t in pose for t in gone) and not all(t in gone for t in pose):
            gone = [t for t in gone if t not in pose]
        return tuple(gone)

    def _passthrough(self, names: Iterable[str]) -> dict[str, str]:
        """``{file name: schema name}`` of the columns read by their own (format 2 or 1) name."""
        out: dict[str, str] = {}
        for name in names:
            schema = FORMAT1_NAMES.get(name, name)
            if schema in _BY_NAME and schema not in self.targets and schema not in out.values():
                out[name] = schema
        return out

    def apply(self, cells: Mapping[str, Sequence[str]], rows: int, source: str, *, merged: bool = False) -> dict:
        """The schema columns from the file's ``cells`` (``{name: rows strings}``, the names
        of :meth:`columns_to_read`). Errors are :class:`LogError` at ``row + 2`` (the
        :func:`~simrunner.telemetry.log.log_from_columns` convention; read_log maps them to lines).
        ``merged`` (a merged topic log, :mod:`simrunner.telemetry.sparse`): an empty cell is NaN,
        and so is a rule's value in a row where a column it uses is empty."""
        numbers: dict[str, np.ndarray] = {}

        def number(name: str) -> np.ndarray:
            if name not in numbers:
                numbers[name] = _numbers(name, cells[name], source, merged)
            return numbers[name]

        out: dict = {}
        for rule in self.rules:
            if any(n not in cells for n in rule.sources):  # a sensor this log lacks (partial)
                continue
            if _BY_NAME[rule.target].kind == "text":
                out[rule.target] = tuple(cells[rule.sources[0]])
                continue
            values = {name: number(name) for name in rule.sources}
            empty = np.zeros(rows, dtype=bool)
            for v in values.values():
                empty |= np.isnan(v)
            if rule.nonzero:
                zero = np.flatnonzero(np.all([values[n] == 0.0 for n in rule.nonzero], axis=0))
                if zero.size:
                    raise LogError(source, int(zero[0]) + 2,
                                   f"{rule.target} ({rule.origin}): quaternion {', '.join(rule.nonzero)} "
                                   f"is all zero: expected a rotation")
            try:
                value = np.array(np.broadcast_to(rule.expression.evaluate(values, self.norms), (rows,)),
                                 dtype=float)
            except NormFault as fault:
                raise LogError(source, fault.row + 2, f"{rule.target} = {rule.expression.text!r} "
                                                      f"({rule.origin}): {fault.message}") from None
            value[empty] = np.nan
            bad = np.flatnonzero(~np.isfinite(value) & ~empty)
            if bad.size:
                i = int(bad[0])
                raise LogError(source, i + 2, f"{rule.target} = {rule.expression.text!r} ({rule.origin}) gives "
                                              f"{float(value[i])!r}: expected a finite number")
            out[rule.target] = value
        for name, schema in self._passthrough(cells).items():
            out[schema] = tuple(cells[name]) if _BY_NAME[schema].kind == "text" else number(name)
        return out


def _numbers(name: str, cells: Sequence[str], source: str, merged: bool = False) -> np.ndarray:
    out = np.empty(len(cells))
    for i, cell in enumerate(cells):
        if merged and is_empty_cell(cell):
            out[i] = np.nan
            continue
        try:
            v = float(cell)
        except ValueError:
            raise LogError(source, i + 2, f"column {name!r}: expected a number (got {cell!r})") from None
        if not math.isfinite(v):
            raise LogError(source, i + 2, f"column {name!r}: expected a finite number (got {cell!r})")
        out[i] = v
    return out


def column_map_from(file: str | Path | None = None, items: Iterable[str] = (),
                    norms: Mapping[str, Callable[[float, float], float]] | None = None,
                    norms_from: str = "--norms") -> ColumnMap:
    """The map of ``simrunner gap --columns FILE --column ITEM ... --norms CONTROLLER.py``:
    the TOML file's rules, with the command-line ``items`` (``NAME=EXPR``) replacing or
    adding rules; ``norms`` (:func:`simrunner.run.norms.controller_norms`) for the rules that
    call ``speed_norm``/``turn_norm``. A rule that calls one without ``norms``, or ``norms``
    that no rule calls, is a :class:`ColumnMapError`."""
    base = ColumnMap.from_toml(file) if file is not None else ColumnMap()
    out = base.merged(ColumnMap.from_items(items))
    calling = [r for r in out.rules if r.expression.norms]
    if norms is None and calling:
        r = calling[0]
        raise ColumnMapError(r.origin, f"{r.target} calls {r.expression.norms[0]}: expected the controller whose "
                                       "norm functions it means: --norms CONTROLLER.py")
    if norms is not None and not calling:
        raise ColumnMapError(Origin(norms_from, 0), "no column rule calls speed_norm or turn_norm: expected e.g. "
                                                    "--column 'speed_cmd_mps=speed_norm(duty, servo)' --column "
                                                    "'steer_cmd_rad=turn_norm(duty, servo)'")
    return dataclasses.replace(out, norms=norms) if norms is not None else out


def read_mapped_logs(paths: Sequence[str | Path], mapping: ColumnMap, **read_kw) -> list:
    """Several logs of one car read with one ``mapping`` (``read_kw``: the rest of
    :func:`~simrunner.telemetry.log.read_log`'s options): one log as the map says; several each
    with the sensors it has (:attr:`ColumnMap.partial`), a rule that no log can follow being
    a :class:`ColumnMapError` at the rule's line."""
    if len(paths) == 1:
        return [read_log(paths[0], columns=mapping, **read_kw)]
    partial = dataclasses.replace(mapping, partial=True)
    logs = [read_log(path, columns=partial, **read_kw) for path in paths]
    for rule in mapping.rules:
        if rule.target not in NEEDED and all(getattr(log, rule.target, None) is None for log in logs):
            raise ColumnMapError(rule.origin, f"{rule.target} asks for column {', '.join(map(repr, rule.sources))}, "
                                              f"which none of the {len(paths)} logs has: expected it in one of them")
    return logs


__all__ = ["ColumnMap", "ColumnRule", "ColumnMapError", "Expression", "Origin", "UNITS", "FUNCTIONS",
           "NORM_FUNCTIONS", "NormFault", "column_map_from", "read_mapped_logs"]
