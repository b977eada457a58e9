"""Controller parameters: ``simrunner drive CTL --param NAME=VALUE`` -> ``RunSettings.params``
-> ``spinner.param(name, default)`` in the controller (docs/drive.md, "Parameters").

Values are parsed once, as people type them: a whole number is an ``int`` (``3``, ``-2``), a
decimal or exponent number a ``float`` (``1.5``, ``2e-3``), anything else a ``str``
(``left``). ``spinner.param(name, default)`` converts the value to the type of ``default``
(``int`` accepts whole floats, ``float`` accepts ints, ``bool`` accepts true/false/1/0/yes/no,
``str`` takes the value as text); a parameter not given returns ``default``.
"""
from __future__ import annotations

import math
import re
from types import MappingProxyType
from typing import Any, Mapping

from simrunner.errors import CommandError, SimError

ParamValue = int | float | str

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.]{0,63}\Z")
_INT = re.compile(r"[+-]?\d+\Z")
_FLOAT = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
_TRUE, _FALSE = {"true", "yes", "on", "1"}, {"false", "no", "off", "0"}


class ParamError(SimError):
    """A ``--param`` that cannot be parsed (the message names it and what was expected)."""


def parse_value(text: str) -> ParamValue:
    """``"3"`` -> 3, ``"1.5"`` -> 1.5, ``"left"`` -> ``"left"`` (see the module docstring)."""
    t = text.strip()
    if _INT.match(t):
        return int(t)
    if _FLOAT.match(t):
        value = float(t)
        if math.isfinite(value):
            return value
    return text


def check_name(name: str, where: str = "--param") -> str:
    if not isinstance(name, str) or not _NAME.match(name):
        raise ParamError(f"{where} {name!r}: expected a name of letters, digits, '_' or '.' "
                         "(not starting with a digit)")
    return name


def parse_param(text: str) -> tuple[str, ParamValue]:
    """``"NAME=VALUE"`` -> ``(name, value)``; raises :class:`ParamError`."""
    name, sep, value = text.partition("=")
    if not sep:
        raise ParamError(f"--param {text!r}: expected NAME=VALUE, e.g. --param speed=1.5")
    return check_name(name.strip()), parse_value(value)


def parse_params(items: list[str] | tuple[str, ...]) -> dict[str, ParamValue]:
    """Several ``NAME=VALUE`` texts -> a dict; a name given twice raises :class:`ParamError`."""
    out: dict[str, ParamValue] = {}
    for item in items:
        name, value = parse_param(item)
        if name in out:
            raise ParamError(f"--param {name} given twice ({name}={out[name]!r} and {item!r})")
        out[name] = value
    return out


def frozen_params(params: Mapping[str, Any] | None) -> Mapping[str, ParamValue]:
    """A read-only copy of ``params`` (names checked; values int, float or str)."""
    out: dict[str, ParamValue] = {}
    for name, value in dict(params or {}).items():
        check_name(name, "params")
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise ParamError(f"params[{name!r}] = {value!r}: expected an int, float or str")
        if isinstance(value, float) and not math.isfinite(value):
            raise ParamError(f"params[{name!r}] = {value!r}: expected a finite number")
        out[name] = value
    return MappingProxyType(out)


def convert(name: str, value: ParamValue, default: Any) -> Any:
    """``value`` as the type of ``default`` (None: unchanged); raises :class:`CommandError`."""
    if default is None:
        return value
    want = type(default)
    if isinstance(default, bool):
        text = str(value).strip().lower()
        if text in _TRUE or text in _FALSE:
            return text in _TRUE
    elif isinstance(default, int):
        if isinstance(value, int):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
    elif isinstance(default, float):
        if isinstance(value, (int, float)):
            return float(value)
    elif isinstance(default, str):
        return value if isinstance(value, str) else repr(value) if isinstance(value, float) else str(value)
    else:
        raise CommandError(f"param({name!r}, {default!r}): expected a default of type int, "
                           "float, bool, str or None")
    raise CommandError(f"param {name}={value!r}: expected a value of type {want.__name__} "
                       f"(the type of the default {default!r})")


def unused_params_text(unused, read) -> str:
    """What a run that never read the ``--param`` names ``unused`` says of them: the names it did
    read (``read``: its own and its kit library's), the nearest as a "did you mean"."""
    import difflib

    unused, read = sorted(unused), sorted(read)
    text = "the controller never read --param " + ", ".join(unused)
    if not read:
        return text + " (read one with spinner.param(name, default); C: spinner_param)"
    # (none for another number of a family read: s32k_pin_7 is another channel, no typo of s32k_pin_6)
    near = [m for name in unused if not any(_other_number(name, r) for r in read)
            for m in difflib.get_close_matches(name, read, n=1, cutoff=0.7)]
    mean = f"; did you mean {', '.join(dict.fromkeys(near))}?" if near else ""
    return f"{text} (it read {', '.join(_numbered_as_one(read))}{mean})"


def _other_number(a: str, b: str) -> bool:
    """``a`` and ``b`` are ``prefix_<number>`` of one prefix."""
    import re

    ma, mb = re.fullmatch(r"(.+_)(\d+)", a), re.fullmatch(r"(.+_)(\d+)", b)
    return bool(ma and mb and ma[1] == mb[1])


def _numbered_as_one(names: list[str]) -> list[str]:
    """``names`` (sorted) with each family of two or more ``prefix_<number>`` names as one,
    ``prefix_{6,32,33}`` (a kit's lookup per channel, ``s32k_pin_N`` for each Dio channel the
    firmware used, is one name of the kit's, not a list of things the program read)."""
    import re

    families: dict[str, list[int]] = {}
    for name in names:
        m = re.fullmatch(r"(.+_)(\d+)", name)
        if m:
            families.setdefault(m[1], []).append(int(m[2]))
    out, done = [], set()
    for name in names:
        m = re.fullmatch(r"(.+_)(\d+)", name)
        if m and len(families[m[1]]) >= 2:
            if m[1] not in done:
                done.add(m[1])
                out.append(m[1] + "{" + ",".join(map(str, sorted(families[m[1]]))) + "}")
            continue
        out.append(name)
    return out

