"""Where a C/C++ program delays with an empty counting loop.

Student firmware often waits with ``for (i = 0; i < 100000 * x; i++);``: on the MCU the loop costs
its iterations x a few cycles of the core clock. Here the car's code runs in no simulated time
between the kit's calls (and -O2 removes such a loop without ``volatile``), so the car's motors are
set and reset at the same instant and it never moves. :func:`delay_loops` finds those loops in the
user's own sources and headers by a scan of their text (comments and strings removed first), for
``simrunner check`` and ``drive`` to warn at file:line (:func:`delay_warnings`).

A loop is one when its body is empty (``;`` or ``{}``) and its condition counts: it changes a
counter (``while (n--);``, ``do {} while (--n);``; a ``for``'s increment) and reads nothing but that
counter, numbers, arithmetic, locals and parameters of its function and constants (a name in
capitals or a ``#define``). A call, an index, a pointer's dereference, a member or another global
in the condition is a loop polling something the kit or an interrupt changes - which works, the
kit lets time pass while polling - and is not flagged; nor is a loop with a body.

Macros are seen only as written: a ``#define DELAY(x) for (i = 0; i < (x); i++);`` in the user's own
source or header is found at the macro's definition line (its parameters count as locals), not
where it is used; a macro from a kit's or the system's header is not the user's code.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from simrunner.run.hostclock import SHOWN as CLOCK_SHOWN, place_warnings

#: places worded one by one; the rest are counted in one more line (the clock reads' number)
SHOWN = CLOCK_SHOWN

#: the kit's call that waits in simulated time (``--kit``; None: a plain C/C++ program)
WAIT_CALLS = {None: "spinner_sleep(seconds) / usleep(us)", "tfc": "TFC_Delay_mS(ms)",
              "tfc-mbed": "wait_ms(ms) / wait(s)", "s32k144": "OsIf_TimeDelay(ms)"}

_KEYWORDS = frozenset("""auto break case char const continue default do double else enum extern float for goto if
    inline int long register restrict return short signed sizeof static struct switch typedef union unsigned void
    volatile while bool true false class new delete namespace template typename this using operator""".split())
_TYPE_WORDS = frozenset("int unsigned long short char signed float double bool const auto".split())
_TOKEN = re.compile(r"\s*(?:(?P<num>\.?\d[\w.]*(?:[eEpP][+-]\d+)?)|(?P<id>[A-Za-z_]\w*)|(?P<op>\+\+|--|->|::|"
                    r"<<=|>>=|[-+*/%&|^<>=!]=|<<|>>|&&|\|\||[-+*/%&|^~!<>=?:,()\[\].{};#\\]))")
_STEP = re.compile(r"^\s*(?:(?:\+\+|--)\s*(?P<pre>[A-Za-z_]\w*)|(?P<post>[A-Za-z_]\w*)\s*(?:\+\+|--)|"
                   r"(?P<comp>[A-Za-z_]\w*)\s*[-+]=\s*[\w\s()+*-]+|"
                   r"(?P<assign>[A-Za-z_]\w*)\s*=\s*(?P=assign)\s*[-+]\s*\w+)\s*$")


@dataclass(frozen=True)
class DelayLoop:
    """An empty counting loop at ``file``:``line``; ``loop``: how the message shows it
    (``for ... i < 100000 * x ...``); ``kit``: the program's ``--kit`` (its wait call is advised)."""

    file: str
    line: int
    loop: str
    kit: str | None = None

    def text(self) -> str:
        """The warning, as ``simrunner check`` and ``drive`` print it."""
        return (f"{self.file}:{self.line}: an empty counting loop ({self.loop}) delays no simulated time here - "
                f"the car's code runs in no time between the kit's calls (and -O2 removes a loop without "
                f"volatile): wait with {WAIT_CALLS.get(self.kit, WAIT_CALLS[None])}, or run with "
                f"--mcu-time measured --mcu-scale N")

    def to_json(self) -> list:
        return [self.file, self.line, self.loop, self.kit]

    @classmethod
    def from_json(cls, item: list) -> "DelayLoop":
        file, line, loop, kit = item
        return cls(str(file), int(line), str(loop), None if kit is None else str(kit))


def delay_warnings(loops: tuple[DelayLoop, ...] | list[DelayLoop]) -> list[str]:
    """The warnings of ``loops``: one per place, the first three, then how many more
    (:func:`~simrunner.run.hostclock.place_warnings`)."""
    return place_warnings(loops, "empty counting loop", "delaying no simulated time")


def delay_loops(own_files: dict[str, str], kit: str | None = None) -> tuple[DelayLoop, ...]:
    """The empty counting loops in ``own_files`` (real path -> the name to show: the user's sources
    and headers, not a kit's or the system's), sorted by file and line; a file that cannot be read
    is skipped."""
    found: list[DelayLoop] = []
    for real, shown in own_files.items():
        try:
            text = Path(real).read_text(encoding="utf-8", errors="replace")
        except OSError:
            continue
        found.extend(DelayLoop(shown, line, loop, kit) for line, loop in scan(text))
    return tuple(sorted(set(found), key=lambda d: (d.file, d.line, d.loop)))


def scan(source: str) -> list[tuple[int, str]]:
    """``(line, loop)`` of each empty counting loop in C/C++ ``source``."""
    code = strip_comments(source)
    constants = set(re.findall(r"^[ \t]*#[ \t]*define[ \t]+([A-Za-z_]\w*)(?![\w(])", code, re.M))
    found: list[tuple[int, str]] = []
    tails: set[int] = set()  # the `while` of each do-while, judged with its `do`
    for m in re.finditer(r"\bdo\b", code):
        body_end = _statement_end(code, m.end())
        w = re.compile(r"\s*while\s*\(").match(code, body_end) if body_end is not None else None
        if w is None:
            continue
        tails.add(w.start() + w.group().index("while"))
        close = _matching(code, w.end() - 1)
        if close is None or not _is_empty(code[m.end():body_end]):
            continue
        cond = code[w.end():close]
        if _counts(cond, _counters(cond), code, m.start(), constants):
            found.append((_line(code, m.start()), f"do {{}} while ({_squeeze(cond)})"))
    for m in re.finditer(r"\b(for|while)\s*\(", code):
        if m.start() in tails:
            continue
        close = _matching(code, m.end() - 1)
        if close is None or not re.compile(r"\s*(?:;|\{\s*\})").match(code, close + 1):
            continue
        inside = code[m.end():close]
        if m.group(1) == "while":
            ok = _counts(inside, _counters(inside), code, m.start(), constants)
            shown = f"while ({_squeeze(inside)})"
        else:
            parts = _split_top(inside, ";")
            if len(parts) != 3 or not parts[1].strip():
                continue
            init, cond, step = parts
            counters = _counters(cond) | {name for piece in _split_top(step, ",")
                                          for name in [_stepped(piece)] if name}
            ok = bool(counters) and _counts(cond, counters, code, m.start(), constants, extra=init)
            shown = f"for ... {_squeeze(cond)} ..."
        if ok:
            found.append((_line(code, m.start()), shown))
    return sorted(found)


def strip_comments(source: str) -> str:
    """``source`` with its comments, string and character literals blanked (their newlines kept, so
    lines and columns stay) and line continuations joined as spaces (a macro keeps its line)."""
    out: list[str] = []
    i, n = 0, len(source)
    while i < n:
        c = source[i]
        two = source[i:i + 2]
        if two == "//":
            j = source.find("\n", i)
            j = n if j < 0 else j
            while j < n and source[j - 1] == "\\":  # (a continued // comment)
                j2 = source.find("\n", j + 1)
                j = n if j2 < 0 else j2
            out.append(re.sub(r"[^\n]", " ", source[i:j]))
            i = j
        elif two == "/*":
            j = source.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", source[i:j]))
            i = j
        elif c in "\"'":
            j = i + 1
            while j < n and source[j] != c and source[j] != "\n":
                j += 2 if source[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(c + re.sub(r"[^\n]", " ", source[i + 1:j - 1]) + c)
            i = j
        elif c == "\\" and source[i + 1:i + 2] == "\n":
            out.append(" \n")
            i += 2
        else:
            out.append(c)
            i += 1
    return "".join(out)


def _line(code: str, pos: int) -> int:
    return code.count("\n", 0, pos) + 1


def _squeeze(text: str) -> str:
    return " ".join(text.split())


def _matching(code: str, open_pos: int) -> int | None:
    """The position of the bracket closing the one at ``open_pos``, or None."""
    pairs = {"(": ")", "{": "}", "[": "]"}
    opener, closer = code[open_pos], pairs[code[open_pos]]
    depth = 0
    for i in range(open_pos, len(code)):
        if code[i] == opener:
            depth += 1
        elif code[i] == closer:
            depth -= 1
            if depth == 0:
                return i
    return None


def _statement_end(code: str, pos: int) -> int | None:
    """Where the statement starting at ``pos`` (after a ``do``) ends: after its ``}`` or ``;``."""
    m = re.compile(r"\s*").match(code, pos)
    i = m.end()
    if i < len(code) and code[i] == "{":
        close = _matching(code, i)
        return None if close is None else close + 1
    depth = 0
    for j in range(i, len(code)):
        if code[j] in "({[":
            depth += 1
        elif code[j] in ")}]":
            depth -= 1
            if depth < 0:
                return None
        elif code[j] == ";" and depth == 0:
            return j + 1
    return None


def _is_empty(body: str) -> bool:
    return re.fullmatch(r"\s*(?:;|\{\s*\})\s*", body) is not None


def _split_top(text: str, sep: str) -> list[str]:
    parts, depth, start = [], 0, 0
    for i, c in enumerate(text):
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == sep and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return parts


def _stepped(piece: str) -> str | None:
    """The variable a ``for``'s increment ``piece`` counts (``i++``, ``--i``, ``i += 2``, ``i = i + 1``)."""
    m = _STEP.match(piece)
    if m is None:
        return None
    return next(v for v in m.group("pre", "post", "comp", "assign") if v)


def _tokens(text: str) -> list[tuple[str, str]] | None:
    """(kind, text) of each token of expression ``text``, or None for what is not an expression."""
    out, i = [], 0
    text = text.rstrip()
    while i < len(text):
        m = _TOKEN.match(text, i)
        if m is None or m.end() == i:
            return None
        kind = m.lastgroup
        out.append((kind, m.group(kind)))
        i = m.end()
    return out


def _counters(cond: str) -> set[str]:
    """The variables ``cond`` itself counts (``n--``, ``++i``, ``i += 1``)."""
    toks = _tokens(cond) or []
    names = set()
    for k, (kind, text) in enumerate(toks):
        if kind != "id":
            continue
        before = toks[k - 1][1] if k else ""
        after = toks[k + 1][1] if k + 1 < len(toks) else ""
        if before in ("++", "--") or after in ("++", "--", "+=", "-="):
            names.add(text)
    return names


def _counts(cond: str, counters: set[str], code: str, pos: int, constants: set[str], extra: str = "") -> bool:
    """Whether ``cond`` (of a loop at ``pos`` of ``code``) reads a counter of ``counters`` and
    otherwise only numbers, arithmetic, casts of built-in types, ``sizeof``, the locals and parameters
    of its function (or its macro's parameters; ``extra``: a ``for``'s init) and constants."""
    toks = _tokens(cond)
    if not toks or not counters:
        return False
    if not any(kind == "id" and text in counters for kind, text in toks):
        return False
    scope = _scope(code, pos) + " " + extra
    for k, (kind, text) in enumerate(toks):
        before = toks[k - 1] if k else ("op", "(")
        after = toks[k + 1][1] if k + 1 < len(toks) else ""
        if kind == "op":
            if text in ("->", ".", "[", "::", "{", "}", ";", "#", "\\", "?", ":") or text.endswith("=") and \
                    text not in ("==", "!=", "<=", ">="):
                if text in ("+=", "-=") and before[1] in counters:
                    continue
                return False  # a member, an index, an assignment to another variable
            if text in ("*", "&") and (before[0] == "op" and before[1] not in (")",)):
                return False  # a dereference, an address
            continue
        if kind != "id":
            continue
        if after == "(" and text != "sizeof":
            return False  # a call
        if text in counters or text in _KEYWORDS or text in constants or _is_constant_name(text):
            if text in _KEYWORDS and text not in _TYPE_WORDS | {"sizeof", "true", "false"} or text == "const":
                return False
            continue
        if not _declared_local(text, scope):
            return False  # a global (or something not known to be local): maybe set elsewhere
    return True


def _is_constant_name(name: str) -> bool:
    return any(c.isalpha() for c in name) and name.upper() == name


def _scope(code: str, pos: int) -> str:
    """The text of the function (from its parameters) or ``#define`` holding ``pos``, up to ``pos``."""
    start = code.rfind("\n", 0, pos) + 1
    if re.match(r"[ \t]*#[ \t]*define\b", code[start:pos]):
        return code[start:pos]
    depth, outer = 0, None
    for i in range(pos - 1, -1, -1):
        c = code[i]
        if c == "}":
            depth += 1
        elif c == "{":
            if depth == 0:
                outer = i
            else:
                depth -= 1
    if outer is None:
        return ""
    head = max(code.rfind(";", 0, outer), code.rfind("}", 0, outer), code.rfind("\n#", 0, outer))
    return code[head + 1:pos]


def _declared_local(name: str, scope: str) -> bool:
    """Whether ``scope`` declares ``name`` (``int x``, ``uint32_t *x``, ``const int x = ...``, a
    parameter ``(int x)``; in a ``#define NAME(a, b)``, a parameter), not ``volatile``/``static``/``extern``."""
    macro = re.match(r"[ \t]*#[ \t]*define[ \t]+\w+\(([^)]*)\)", scope)
    if macro:
        return name in {p.strip() for p in macro.group(1).split(",")}
    for m in re.finditer(rf"\b([A-Za-z_]\w*)([\s*&]+)(?:const\s+)?{re.escape(name)}\s*[=;,)\[]", scope):
        word = m.group(1)
        if word in _KEYWORDS and word not in _TYPE_WORDS:
            continue  # (return x;, case x:, ...)
        cut = max(scope.rfind(c, 0, m.start()) for c in ";{}(,")
        if re.search(r"\b(?:volatile|static|extern)\b", scope[cut + 1:m.start()] + " " + word):
            return False
        return True
    return False
