"""Writing the run-log CSV as the run goes: :class:`CsvStream`.

Each row closed by the :class:`~simrunner.telemetry.log.RunRecorder` is formatted exactly as
:func:`simrunner.telemetry.log.write_log` formats it (same format line, header, ``%d`` / ``%.6f``
and quoting: the same run gives the same bytes either way) and written at once with one
``os.write`` of whole lines, so the file on disk holds every row closed so far whatever ends
the process (a crash, ``os._exit``, a hard kill): at most the open row is missing. (A kill
that lands inside that one write can leave the row cut short; :func:`~simrunner.telemetry.log.read_log`
leaves such a last line out with a ``LogWarning``. tests/test_run_hard_end.py kills a run.) The file
is the requested path itself (not a temporary renamed at the end): a run that was cut short
still leaves its telemetry where it was asked for. Nothing of the rows is kept here.

A write error (disk full, ...) stops the writing; :meth:`close` then raises a
:class:`~simrunner.telemetry.log.LogError` naming the path, after the run has ended normally.
"""
from __future__ import annotations

import os
from pathlib import Path

from simrunner.telemetry.log import COLUMNS, EXTRA_COLUMNS, FORMAT_LINE, LogError, _quote
from trackgen.outdir import process_umask

# the run's columns in schema order (the extra columns only when the run records them); coast is
# always 0 in a simulated run
_BASE = [c for c in COLUMNS if c.name not in EXTRA_COLUMNS]
_LINE = ",".join(c.fmt for c in _BASE) + "\n"
_HEADER = FORMAT_LINE + "\n" + ",".join(c.name for c in _BASE) + "\n"


class CsvStream:
    """Writes ``path``: created (truncated) with the header at the first :meth:`row`, which
    appends one row (``values``: the 13 numbers of a ``RunRecorder`` row and its ``extra``
    columns' values, ``text``: its data_text). :meth:`discard` removes what was written (a run
    that did not start)."""

    def __init__(self, path: str | Path, *, extra: tuple[str, ...] = (), umask: int | None = None):
        self.path = Path(path).absolute()  # opened at the first row: a controller's chdir must not move it
        # nor its umask change the file's (and folders') permissions (umask: the caller's, None: now)
        self._umask = process_umask() if umask is None else umask
        self._mode = 0o666 & ~self._umask
        self.extra = tuple(extra)
        if self.extra:
            cols = _BASE[:-1] + [c for c in COLUMNS if c.name in self.extra] + _BASE[-1:]
            self._line = ",".join(c.fmt for c in cols) + "\n"
            self._header = FORMAT_LINE + "\n" + ",".join(c.name for c in cols) + "\n"
        self.rows = 0
        self._error: OSError | None = None
        self._fd: int | None = None
        self._closed = False

    def _open(self) -> None:
        """Create the file at the first row (a run that never starts writes nothing)."""
        try:
            made = []  # the folders it creates: with the mask from before the run, as the file
            folder = self.path.parent
            while not folder.exists() and folder != folder.parent:
                made.append(folder)
                folder = folder.parent
            if made:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                for folder in made:
                    try:
                        os.chmod(folder, 0o777 & ~self._umask)
                    except OSError:  # a file system without modes: as it was created
                        pass
            created = not self.path.exists()
            self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
        except OSError as exc:
            self._error = exc
            return
        if created:
            try:
                os.fchmod(self._fd, self._mode)
            except OSError:  # a file system without modes: as it was created
                pass
        self._write(self._header if self.extra else _HEADER)

    def _write(self, text: str) -> None:
        if self._fd is None or self._error is not None:
            return
        data = text.encode("utf-8")
        try:
            while data:
                data = data[os.write(self._fd, data):]
        except OSError as exc:
            self._error = exc

    def row(self, values: tuple, text: str) -> None:
        if self._fd is None:
            if self._closed or self._error is not None:
                return
            self._open()
        v = values
        if self.extra:
            self._write(self._line % (v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10],
                                      0, v[11], 1 if v[12] else 0, *v[13:], _quote(text) if text else ""))
        else:
            self._write(_LINE % (v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10],
                                 0, v[11], 1 if v[12] else 0, _quote(text) if text else ""))
        self.rows += 1

    def close(self) -> Path:
        """Close the file (a run without rows still gets the header); raise :class:`LogError`
        if a write failed."""
        if self._fd is None and not self._closed and self._error is None:
            self._open()
        self._closed = True
        if self._fd is not None:
            try:
                os.close(self._fd)
            except OSError as exc:
                self._error = self._error or exc
            self._fd = None
        if self._error is not None:
            raise LogError(str(self.path), 0, f"cannot write the log ({self._error.strerror})")
        return self.path

    def discard(self) -> None:
        """Close and remove the file if this stream created it."""
        created = self._fd is not None
        self._closed = True
        if self._fd is not None:
            try:
                os.close(self._fd)
            except OSError:
                pass
            self._fd = None
        if created:
            self.path.unlink(missing_ok=True)
