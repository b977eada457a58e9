"""Windows spellings of ``#include`` names in a kit firmware (``simrunner drive ... --kit``).

Kit firmware comes from Windows IDEs (CodeWarrior, Kinetis Design Studio, S32 Design Studio),
whose compilers find ``#include "TFC\\ENKODER.h"`` (a backslash) and ``#include "Math.h"`` (a
file named ``math.h``, or ``common.h`` for ``Common.h``): Windows file names ignore case and
take either slash. GCC on a case-sensitive system with ``/`` finds neither. :func:`include_shims`
reads the sources and the project headers they include, and for each name that does not resolve
as written but does the Windows way, gives a one-line header of that spelling that includes
the file it means (written by :func:`write_shims` into a folder put on the include path). Names
that resolve as written are left alone, so a build that works unchanged stays unchanged.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

INCLUDE_RE = re.compile(rb'^[ \t]*#[ \t]*include[ \t]*([<"])([^>"\r\n]+)[>"]', re.M)
#: The C standard library's headers (C11 section 7.1.2), met as ``"Math.h"`` or ``<Stdlib.h>``.
STD_HEADERS = frozenset(
    "assert.h complex.h ctype.h errno.h fenv.h float.h inttypes.h iso646.h limits.h locale.h "
    "math.h setjmp.h signal.h stdalign.h stdarg.h stdatomic.h stdbool.h stddef.h stdint.h "
    "stdio.h stdlib.h stdnoreturn.h string.h tgmath.h threads.h time.h uchar.h wchar.h "
    "wctype.h".split())


def _find_nocase(base: Path, rel: str) -> Path | None:
    """``base/rel`` matched component by component ignoring case, or None."""
    here = base
    for part in rel.split("/"):
        if part in ("", "."):
            continue
        if part == "..":
            here = here.parent
            continue
        exact = here / part
        if exact.exists():
            here = exact
            continue
        try:
            names = os.listdir(here)
        except OSError:
            return None
        match = sorted(n for n in names if n.lower() == part.lower())
        if not match:
            return None
        here = here / match[0]
    return here if here.is_file() else None


def include_shims(sources: list[Path], include_dirs: list[Path],
                  limit_files: int = 2000) -> dict[str, str]:
    """``{spelling: include line}`` for every ``#include`` name in ``sources`` and the project
    headers they reach (through ``include_dirs``, searched as the compiler does: a quoted name
    first beside the file that includes it) that resolves only the Windows way."""
    dirs = [Path(d) for d in include_dirs]
    shims: dict[str, str] = {}
    todo = [Path(s).resolve() for s in sources]
    seen: set[Path] = set()
    while todo and len(seen) < limit_files:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        try:
            text = path.read_bytes()
        except OSError:
            continue
        for kind, raw in INCLUDE_RE.findall(text):
            name = raw.decode("utf-8", "replace").strip()
            search = ([path.parent] if kind == b'"' else []) + dirs
            exact = next((d / name for d in search if (d / name).is_file()), None)
            if exact is not None:
                todo.append(exact.resolve())
                continue
            if name in shims:
                continue
            windows = name.replace("\\", "/")
            found = next((f for f in (_find_nocase(d, windows) for d in search) if f is not None),
                         None)
            if found is not None:
                shims[name] = f'#include "{found.resolve()}"\n'
                todo.append(found.resolve())
            elif windows.lower() in STD_HEADERS and windows != windows.lower():
                shims[name] = f"#include <{windows.lower()}>\n"
    return shims


def write_shims(folder: Path, shims: dict[str, str]) -> None:
    """Write each shim of :func:`include_shims` as ``folder/spelling`` (a spelling with ``/``
    in a sub-folder; one with ``..`` is skipped: it cannot be a file under ``folder``)."""
    for name, line in shims.items():
        if ".." in name.replace("\\", "/").split("/") or name.startswith(("/", "\\")):
            continue
        target = folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(line)
