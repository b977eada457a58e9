"""Compiling a C controller within limits (issue 50: a generated 9 MB source compiled for
340 s at 3.5 GB with no limit and no word): a wall-time and a memory limit with a one-line
error naming the file, a warning while a build is slow, the CLI's line for each."""
from __future__ import annotations

import shutil
import stat
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.errors import ControllerFileError
from simrunner.run.native import BuildLimits, BuildWarning, build_program

pytestmark = pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SIMRUNNER_CACHE_DIR", str(tmp_path / "cache"))
    for var in ("SIMRUNNER_BUILD_TIME_S", "SIMRUNNER_BUILD_MEMORY_MB", "CC"):
        monkeypatch.delenv(var, raising=False)


def _slow_compiler(tmp_path: Path) -> tuple[Path, Path]:
    """A stand-in compiler that starts a child (as cc starts cc1) and waits for it; the
    child's pid is written to the returned file."""
    script = tmp_path / "slowcc"
    pidfile = tmp_path / "child.pid"
    script.write_text(f"#!/bin/sh\nsleep 60 &\necho $! > {pidfile}\nwait\n")
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return script, pidfile


def _gone(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/status").read_text().split("State:")[1].split()[0] == "Z"
    except (OSError, IndexError):
        return True


def test_a_build_past_its_time_limit_is_stopped_with_its_children_and_named(tmp_path, monkeypatch):
    script, pidfile = _slow_compiler(tmp_path)
    monkeypatch.setenv("CC", str(script))
    src = tmp_path / "ctl.c"
    src.write_text("int main(void) { return 0; }\n")
    limits = BuildLimits(wall_s=1.0, slow_after_s=0.3, slow_every_s=10.0)
    with pytest.warns(BuildWarning, match=r"compiling .*ctl\.c: 0 s so far \(stopped at 1 s or 2048 MB\)"):
        with pytest.raises(ControllerFileError, match=r"ctl\.c: compiling stopped at the build time "
                                                      r"limit of 1 s \(SIMRUNNER_BUILD_TIME_S="):
            build_program([src], limits=limits)
    child = int(pidfile.read_text())
    for _ in range(50):  # killed with the compiler's process group (reaped by init)
        if _gone(child):
            break
        time.sleep(0.05)
    assert _gone(child)
    assert not [p for p in (tmp_path / "cache" / "native").iterdir() if p.name.startswith(".build-")]


def _heavy_source(tmp_path: Path) -> Path:
    """A 150 kB function that needs ~170 MB to compile (measured: fails at 80 MB in 0.2 s)."""
    body = "\n".join(f"  acc += x * {i}.5 + (acc > {i} ? x / {i + 1}.0 : x * x);" for i in range(2500))
    src = tmp_path / "heavy.c"
    src.write_text("volatile double acc;\nstatic void big(double x) {\n" + body + "\n}\n"
                   "int main(void) { big(1.0); return 0; }\n")
    return src


def test_a_build_past_its_memory_limit_is_one_line_naming_the_file(tmp_path):
    src = _heavy_source(tmp_path)
    with pytest.raises(ControllerFileError) as err:
        build_program([src], limits=BuildLimits(memory_mb=80))
    assert str(err.value) == (f"{src}: compiling needed more than the build memory limit of 80 MB "
                              "(SIMRUNNER_BUILD_MEMORY_MB=MB sets another)")


def test_the_cli_says_a_build_is_slow_and_why_it_stopped(tmp_path, monkeypatch):
    src = _heavy_source(tmp_path)
    monkeypatch.setenv("SIMRUNNER_BUILD_MEMORY_MB", "80")
    r = CliRunner().invoke(cli, ["drive", str(src), "--track", "floor"])
    assert r.exit_code == 2
    assert r.output == (f"simrunner: {src}: compiling needed more than the build memory limit of 80 MB "
                        "(SIMRUNNER_BUILD_MEMORY_MB=MB sets another)\n")
    script, _ = _slow_compiler(tmp_path)
    monkeypatch.setenv("CC", str(script))
    monkeypatch.setenv("SIMRUNNER_BUILD_TIME_S", "6")
    r = CliRunner().invoke(cli, ["drive", str(src), "--track", "floor"])
    assert r.exit_code == 2
    assert r.output.splitlines() == [
        f"simrunner: warning: compiling {src} ({src.stat().st_size / 1e6:.1f} MB): 5 s so far "
        "(stopped at 6 s or 80 MB)",
        f"simrunner: {src}: compiling stopped at the build time limit of 6 s "
        "(SIMRUNNER_BUILD_TIME_S=SECONDS sets another)"]


@pytest.mark.parametrize("value", ["0", "-3", "lots"])
def test_a_bad_limit_in_the_environment_is_one_line(monkeypatch, value):
    monkeypatch.setenv("SIMRUNNER_BUILD_TIME_S", value)
    with pytest.raises(ControllerFileError, match=rf"^SIMRUNNER_BUILD_TIME_S={value}: expected a number > 0 \(seconds\)$"):
        BuildLimits.from_env()


def test_ordinary_builds_are_within_the_default_limits(tmp_path):
    src = tmp_path / "ok.c"
    src.write_text('#include "spinner.h"\nint main(void) { spinner_sleep(0.01); return 0; }\n')
    assert build_program([src], limits=BuildLimits.from_env()).library.is_file()
