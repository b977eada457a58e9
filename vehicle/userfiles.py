"""Reading the small text files users write (car descriptions, measurements, plans) with
one-line errors that name the file; shared by ``worlds`` and ``simrunner``."""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any


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
