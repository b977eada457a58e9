"""Both command lines: -h like --help, --version; drive's options spelt as the API names."""
from __future__ import annotations

import inspect
import subprocess
import sys
from dataclasses import fields
from importlib.metadata import version
from pathlib import Path

import pytest
from click.testing import CliRunner

from simrunner.cli import drive_cmd, main as simrunner_main
from simrunner.run.runner import drive
from simrunner.run.settings import RunSettings
from trackgen.cli import main as trackgen_main

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("cli, args", [
    (simrunner_main, []), (simrunner_main, ["drive"]), (simrunner_main, ["plot"]),
    (simrunner_main, ["gap"]), (trackgen_main, []), (trackgen_main, ["build"]),
])
def test_dash_h_is_help(cli, args):
    short = CliRunner().invoke(cli, [*args, "-h"])
    long = CliRunner().invoke(cli, [*args, "--help"])
    assert short.exit_code == long.exit_code == 0, short.output
    assert short.output == long.output and "Usage:" in short.output


@pytest.mark.parametrize("cli, name", [(simrunner_main, "simrunner"), (trackgen_main, "trackgen")])
def test_version(cli, name):
    r = CliRunner().invoke(cli, ["--version"])
    assert r.exit_code == 0 and r.output == f"{name}, version {version('nxpcup-sim')}\n"


def test_version_of_the_installed_command():
    done = subprocess.run([sys.executable, "-c", "from simrunner.cli import main; main()",
                           "--version"], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert done.returncode == 0 and done.stdout.startswith("simrunner, version ")


def _api_names() -> set[str]:
    names = {p for p in inspect.signature(drive).parameters if p not in ("controller", "settings",
                                                                         "setting_values")}
    return names | {f.name for f in fields(RunSettings)}


def test_every_drive_keyword_is_a_cli_option_of_the_same_name():
    opts = {o for p in drive_cmd.params for o in getattr(p, "opts", [])}
    missing = sorted(n for n in _api_names() if "--" + n.replace("_", "-") not in opts)
    assert not missing, f"drive() keywords without a --same-name option: {missing}"


def test_api_spelling_and_short_spelling_both_work(tmp_path):
    ctrl = tmp_path / "c.py"
    ctrl.write_text("def main(spinner):\n    spinner.sleep(0.5)\n")
    for flag in ("--time-limit", "--time-limit-s"):
        r = CliRunner().invoke(simrunner_main, ["drive", str(ctrl), flag, "0.2", "--dt-s", "0.004"])
        assert r.exit_code == 1 and "time limit of 0.2 s" in r.output, r.output


def test_dash_h_still_works_after_a_command_ran_on_its_own():
    """click keeps a command's help option from its first invocation: a lazily loaded command
    (gap) invoked on its own first then refused -h under simrunner (seen in a test order)."""
    from simrunner.cli.gap import gap
    from trackgen.cli import build

    for alone, cli, args in ((gap, simrunner_main, ["gap"]), (drive_cmd, simrunner_main, ["drive"]),
                             (build, trackgen_main, ["build"])):
        assert CliRunner().invoke(alone, ["--help"]).exit_code == 0
        r = CliRunner().invoke(cli, [*args, "-h"])
        assert r.exit_code == 0 and "Usage:" in r.output, r.output
