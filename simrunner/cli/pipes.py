"""Standard output whose reader may go away (``simrunner drive ctl.py | head -n1``).

Python ignores SIGPIPE, so a write to a pipe nobody reads any more raises BrokenPipeError
wherever it happens: in a controller's ``print`` (which then ended the run as
``controller_error``, with that traceback), or in the lines the command prints after the
run. :func:`tolerate_reader_leaving` makes ``sys.stdout`` drop what it is given once the
reader has gone (file descriptor 1 is pointed at ``/dev/null`` then, so C code in this
process and processes started after it write there too): the command does its whole work
(the run, its files) and ends with its own exit status. Only a pipe or socket on stdout
is wrapped: a terminal, a file or a test runner's stream is left as it is.
"""
from __future__ import annotations

import io
import os
import stat
import sys


class _ReaderMayLeave(io.RawIOBase):
    """File descriptor ``fd`` as a raw stream: after the first EPIPE every write succeeds
    without output (``fd`` then refers to ``/dev/null``)."""

    def __init__(self, fd: int):
        super().__init__()
        self._fd = fd

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def write(self, data) -> int:
        try:
            return os.write(self._fd, data)
        except BrokenPipeError:
            _to_null(self._fd)
            return len(data)


def _to_null(fd: int) -> None:
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, fd)
    os.close(null)


def tolerate_reader_leaving() -> None:
    """Replace ``sys.stdout`` by one that survives its reader leaving (module docstring);
    does nothing unless stdout is a pipe or a socket (or is already such a stream)."""
    out = sys.stdout
    if isinstance(out, io.TextIOWrapper) and isinstance(out.buffer, io.BufferedWriter) \
            and isinstance(out.buffer.raw, _ReaderMayLeave):
        return
    try:
        fd = out.fileno()
        mode = os.fstat(fd).st_mode
    except (AttributeError, OSError, ValueError):  # a test runner's in-memory stream
        return
    if not (stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode)):
        return
    try:
        out.flush()
    except BrokenPipeError:  # gone already: what it held goes nowhere
        _to_null(fd)
        out.flush()
    sys.stdout = io.TextIOWrapper(io.BufferedWriter(_ReaderMayLeave(fd)), encoding=out.encoding,
                                  errors=out.errors, line_buffering=out.line_buffering,
                                  write_through=getattr(out, "write_through", False))  # python -u
