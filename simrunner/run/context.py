"""The session of the run executing in this context (thread): what ``Spinner()`` built inside
``main`` attaches to (as in the thesis) and what the fault handlers of :mod:`.faults` ask for.
A context variable, not a module global: two runs in two threads each see their own."""
from __future__ import annotations

import contextvars

# a simrunner.run.spinner.Session, or None outside a run
SESSION: contextvars.ContextVar = contextvars.ContextVar("simrunner_session", default=None)


def current_session():
    """The :class:`~simrunner.run.spinner.Session` of the run executing in this context (None
    outside a run)."""
    return SESSION.get()
