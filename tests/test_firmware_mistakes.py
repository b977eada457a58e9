"""What a team's common firmware mistakes print: one line saying what and where (file:line) and
what to do, no traceback (a kit header built without --kit, a header of the project's own without
its -I, a typo'd function, a source file left out, a --param the firmware never reads)."""
from __future__ import annotations

import gc
import sys
import textwrap

import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.errors import ControllerFileError
from simrunner.run.native import build_program
from simrunner.run.native import controller as controller_module
from simrunner.run.native.controller import NativeController

MAIN = """\
    #include "derivative.h"
    #include "TFC\\TFC.h"
    #include "control.h"
    int main(void) {
        TFC_Init();
        Control_Init();
        for (;;) { TFC_Task(); if (TFC_Ticker[0] > 300) return 0; }
    }
    """
CONTROL = """\
    #include "TFC\\TFC.h"
    #include "control.h"
    void Control_Init(void) { TFC_SetServ0(0, 0.5f); }
    """


@pytest.fixture
def project(tmp_path):
    """A CodeWarrior-style project: Sources/main.c, Sources/control.c, Project_Headers/control.h."""
    (tmp_path / "Sources").mkdir()
    (tmp_path / "Project_Headers").mkdir()
    (tmp_path / "Sources" / "main.c").write_text(textwrap.dedent(MAIN))
    (tmp_path / "Sources" / "control.c").write_text(textwrap.dedent(CONTROL))
    (tmp_path / "Project_Headers" / "control.h").write_text("void Control_Init(void);\n")
    return tmp_path


def test_a_missing_include_names_the_kit_or_the_folder_to_add(project, monkeypatch):
    monkeypatch.chdir(project)
    with pytest.raises(ControllerFileError) as err:  # the kit's header without --kit
        build_program(["Sources/main.c"], include_dirs=["Project_Headers"])
    assert str(err.value).splitlines()[-1] == ("derivative.h: a header of the simulator's --kit tfc: "
                                               "build with --kit tfc (docs/firmware.md)")
    with pytest.raises(ControllerFileError) as err:  # the project's header without its -I
        build_program(["Sources/main.c"], kit="tfc")
    assert "Sources/main.c:3:10: fatal error: control.h" in str(err.value)
    assert str(err.value).splitlines()[-1] == "control.h is in Project_Headers: add -I Project_Headers"
    # simrunner batch shortens the compiler's words to four lines and keeps what to do
    res = CliRunner().invoke(cli, ["batch", "Sources/main.c", "--kit", "tfc", "-o", "out"])
    assert res.exit_code == 2
    home = project / "Project_Headers"  # (batch names its sources by their full path)
    assert res.stderr.splitlines()[-1] == f"control.h is in {home}: add -I {home}"
    # the other kit's header: named as such (it said "derivative.h is in .../kits/tfc/include: add -I
    # .../kits/tfc/include", a folder of the simulator's, found beside the kit's own sources)
    with pytest.raises(ControllerFileError) as err:
        build_program(["Sources/main.c"], include_dirs=["Project_Headers"], kit="tfc-mbed")
    assert str(err.value).splitlines()[-1] == ("derivative.h: a header of the simulator's --kit tfc, not of "
                                               "--kit tfc-mbed: build with --kit tfc (docs/firmware.md)")
    (project / "Sources" / "mbed_main.cpp").write_text('#include "mbed.h"\nint main() { return 0; }\n')
    with pytest.raises(ControllerFileError) as err:
        build_program(["Sources/mbed_main.cpp"], kit="tfc")
    assert str(err.value).splitlines()[-1] == ("mbed.h: a header of the simulator's --kit tfc-mbed, not of "
                                               "--kit tfc: build with --kit tfc-mbed (docs/firmware.md)")


def test_a_typod_function_and_a_left_out_source_are_one_line_at_their_use(project, monkeypatch, capfd):
    monkeypatch.chdir(project)
    for isolate in ([], ["--isolate"]):  # (isolated: the loader's words come back from the child)
        res = CliRunner().invoke(cli, ["drive", "Sources/main.c", "Sources/control.c", "-I",
                                       "Project_Headers", "--kit", "tfc", *isolate])
        assert res.exit_code == 2 and "Traceback" not in res.output
        assert res.output.splitlines()[-1] == (
            "simrunner: Sources/control.c:3: TFC_SetServ0: no such function in your sources or the "
            "libraries they build with (did you mean TFC_SetServo?)")
        assert "undefined symbol" not in capfd.readouterr().err
    program = build_program(["Sources/main.c"], include_dirs=["Project_Headers"], kit="tfc")
    with pytest.raises(ControllerFileError) as err:
        NativeController(program)
    assert str(err.value) == ("Sources/main.c:6: Control_Init is declared but defined in none of the "
                              "sources given (main.c): pass the source file that defines it")


def test_a_controller_that_cannot_be_loaded_leaves_nothing_for_its_finaliser(project, monkeypatch):
    """Its __del__ once raised AttributeError ("Exception ignored ... Traceback" on stderr)."""
    monkeypatch.chdir(project)
    program = build_program(["Sources/main.c"], include_dirs=["Project_Headers"], kit="tfc")
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", seen.append)
    with pytest.raises(ControllerFileError):
        NativeController(program)
    gc.collect()
    assert seen == []


def test_a_host_that_cannot_be_built_leaves_nothing_for_the_finaliser(project, monkeypatch):
    """The in-process host failing to build (a compiler missing) is the one error: the controller's
    __del__ once raised AttributeError on its unset list of spent libraries."""
    monkeypatch.chdir(project)
    program = build_program(["Sources/main.c"], include_dirs=["Project_Headers"], kit="tfc")

    def fails():
        raise ControllerFileError("compiling the simrunner host program failed: (no compiler)")

    monkeypatch.setattr(controller_module, "host_library", fails)
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", seen.append)
    with pytest.raises(ControllerFileError, match="host program failed"):
        NativeController(program)
    gc.collect()
    assert seen == []


POTS = """\
    #include "derivative.h"
    #include "TFC/TFC.h"
    int main(void) {
        TFC_Init();
        while (TFC_Ticker[0] < 100) TFC_Task();
        TFC_SetServo(0, TFC_ReadPot(0));
        return 0;
    }
    """


def test_a_param_the_firmware_never_reads_names_what_it_read(tmp_path):
    src = tmp_path / "pots.c"
    src.write_text(textwrap.dedent(POTS))
    res = CliRunner().invoke(cli, ["drive", str(src), "--kit", "tfc", "--track", "floor", "--param", "pot=0.5"])
    assert res.exit_code == 0, res.output
    assert res.output.splitlines()[-1] == (
        "simrunner: warning: the controller never read --param pot (it read pot0, "
        "tfc_servo_offset_rad, tfc_servo_rad; did you mean pot0?)")


def test_a_batch_sweeping_a_param_no_run_reads_says_so(tmp_path):
    ctl = tmp_path / "ctl.py"
    ctl.write_text("def main(s):\n    s.param('v_max', 1.0)\n    s.sleep(0.05)\n")
    res = CliRunner().invoke(cli, ["batch", str(ctl), "--time-limit", "0.2", "--param", "vmax=1,2",
                                   "--workers", "1", "--no-plot", "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert ("simrunner batch: warning: the controller never read --param vmax (it read v_max; did you "
            "mean v_max?): its values changed nothing") in res.output
    assert "_params_read" not in (tmp_path / "out" / "results.csv").read_text()


@pytest.mark.parametrize("command", ["drive", "batch"])
def test_mcu_time_without_its_value_names_the_option_not_a_file(tmp_path, command):
    """`--mcu-time --laps 1` once took `--laps` as the time and `1` as a source file ("1: several
    files, -I, -D, --kit and --isr are for C/C++ controllers")."""
    src = tmp_path / "pots.c"
    src.write_text(textwrap.dedent(POTS))
    res = CliRunner().invoke(cli, [command, str(src), "--kit", "tfc", "--mcu-time", "--laps", "1",
                                   "-o", str(tmp_path / "out")][:None if command == "batch" else -2])
    assert res.exit_code == 2
    assert ("Invalid value for '--mcu-time': '--laps': expected measured or seconds per call, e.g. "
            "0.002 (the option's value is missing)") in res.output


@pytest.mark.parametrize("kit, source, hint", [
    ("tfc", """\
        #include "derivative.h"
        #include "TFC\\TFC.h"
        volatile int n;
        void PIT_IRQHandler(void) { PIT_TFLG1 = PIT_TFLG_TIF_MASK; n++; }
        int main(void) {
            TFC_Init();
            PIT_LDVAL1 = 240000 - 1;
            PIT_TCTRL1 = PIT_TCTRL_TEN_MASK | PIT_TCTRL_TIE_MASK;
            for (;;) {
            }
        }
        """, "call TFC_Task() in every loop, or __WFI() in a main loop whose work is the interrupts'"),
    ("tfc-mbed", """\
        #include "mbed.h"
        #include "TFC.h"
        volatile int n;
        void control() { n++; }
        Ticker ticker;
        int main() {
            ticker.attach(&control, 0.01f);
            while (1) {
            }
        }
        """, "call wait(), wait_ms() or sleep() in every loop"),
])
@pytest.mark.parametrize("isolate", [False, True])
def test_a_firmwares_busy_main_loop_is_told_its_kits_idle_call(tmp_path, kit, source, hint, isolate):
    """The interrupt firmware's `for (;;) {}` main loop (the work in a timer's handler) stalls, as
    documented; the message names the line and the kit's calls that let time pass (__WFI(), wait()),
    not Spinner's (it said: call get_image(), sleep() or get_time())."""
    import dataclasses

    from simrunner.run.runner import drive

    src = tmp_path / ("main.c" if kit == "tfc" else "main.cpp")
    src.write_text(textwrap.dedent(source))
    prog = dataclasses.replace(build_program([src], kit=kit), isolate=isolate)
    r = drive(prog, track="floor", time_limit_s=2.0, wall_limit_s=1.0)
    line = 9 if kit == "tfc" else 8
    assert r.outcome == "stalled" and f"main.{src.suffix[1:]}:{line}" in r.message, r.message
    assert hint in r.message and "get_image()" not in r.message, r.message
