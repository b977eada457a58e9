"""Users' files: reading the small text files users write (car descriptions, measurements,
plans) with one-line errors that name the file, and writing every output file whole or not at
all (:func:`write_atomic`). Shared by ``worlds``, ``trackgen`` and ``simrunner``; output
folders are swapped in whole by ``trackgen.outdir``."""
from __future__ import annotations

import os
import threading
import tomllib
from pathlib import Path
from typing import Any, Callable


def write_atomic(path: str | Path, data: str | bytes | Callable[[Path], None]) -> Path:
    """Write ``path`` whole or not at all; return it. ``data``: the text (UTF-8), the bytes, or
    a function that writes the file at the path it is given. It is written into a temporary
    file beside ``path`` (same folder: the last step is a rename, atomic), named after it, this
    process and thread, with its suffix; on any error that file is removed and the error
    (``OSError`` and the like) raised for the caller to word; ``path`` is then untouched."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{threading.get_ident()}.tmp{path.suffix}")
    try:
        if callable(data):
            data(tmp)
        elif isinstance(data, str):
            with open(tmp, "w", encoding="utf-8", newline="") as fh:
                fh.write(data)
        else:
            with open(tmp, "wb") as fh:
                fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        raise
    return path


def read_user_text(path: str | Path, what: str, error: type[Exception], kind: str = "text") -> str:
    """The file's text, or ``error("PATH: cannot read WHAT (reason): expected a readable KIND file")`` /
    ``error("PATH: not a text (KIND) file")``."""
    path = Path(path)
    try:
        return path.read_text()
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc}): expected a readable {kind} file") from None
    except UnicodeDecodeError:
        raise error(f"{path}: not a text ({kind}) file") from None


def read_user_toml(path: str | Path, what: str, error: type[Exception]) -> tuple[str, dict[str, Any]]:
    """``(text, data)`` of a TOML file; errors as :func:`read_user_text` plus
    ``PATH: invalid TOML: ... (at line L, column C)``."""
    text = read_user_text(path, what, error, "TOML")
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: invalid TOML: {exc}") from None
