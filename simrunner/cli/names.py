"""The command line and the Python API name options alike: ``drive(time_limit_s=...)`` is
``--time-limit-s`` as well as the shorter ``--time-limit``.

:func:`add_api_spellings` gives every option of a command the spelling of its Python
keyword (underscores as dashes) when it lacks it, so a name learnt in one works in the
other (tests/test_cli_names.py checks ``drive``'s options against ``drive()`` and
:class:`~simrunner.run.settings.RunSettings`).
"""
from __future__ import annotations

import click

#: Every command's help options: ``-h`` too, also when a command is invoked on its own (click
#: keeps a command's help option from its first invocation: a lazily loaded command invoked
#: alone first would then refuse ``-h`` under ``simrunner``).
HELP = {"help_option_names": ["-h", "--help"]}


def api_spelling(name: str) -> str:
    """``time_limit_s`` -> ``--time-limit-s``."""
    return "--" + name.replace("_", "-")


def add_api_spellings(command: click.Command) -> click.Command:
    """Add ``--python-name`` to each option of ``command`` that is spelt otherwise."""
    for param in command.params:
        if isinstance(param, click.Option) and param.name and not param.hidden:
            spelling = api_spelling(param.name)
            if spelling not in param.opts and spelling not in param.secondary_opts:
                param.opts.append(spelling)
    return command
