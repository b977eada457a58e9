"""Output files whole or not at all (vehicle.userfiles.write_atomic) and output folders swapped
in whole (trackgen.outdir), the two helpers every writer uses (issue 48, item 4)."""
from __future__ import annotations

import ast
import os
import stat
from pathlib import Path

import pytest

from trackgen.outdir import make_temp, replace_folder
from vehicle.userfiles import write_atomic

ROOT = Path(__file__).resolve().parents[1]


def test_text_bytes_and_a_writer_function_land_whole(tmp_path):
    assert write_atomic(tmp_path / "a.txt", "héllo\n").read_text(encoding="utf-8") == "héllo\n"
    assert write_atomic(tmp_path / "b.bin", b"\x00\x01").read_bytes() == b"\x00\x01"
    write_atomic(tmp_path / "c.png", lambda tmp: tmp.write_bytes(b"png" + tmp.suffix.encode()))
    assert (tmp_path / "c.png").read_bytes() == b"png.png"   # the writer sees the file's suffix
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.bin", "c.png"]


def test_a_failing_writer_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old")

    def half(tmp: Path) -> None:
        tmp.write_text("half")
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError):
        write_atomic(target, half)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]


def test_files_get_the_usual_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        mode = stat.S_IMODE(write_atomic(tmp_path / "x.csv", "1\n").stat().st_mode)
    finally:
        os.umask(old)
    assert mode == 0o644


def test_a_folder_is_replaced_whole(tmp_path):
    out = tmp_path / "report"
    for text in ("first", "second"):
        tmp = make_temp(out)
        (tmp / "a.txt").write_text(text)
        replace_folder(tmp, out)
        assert (out / "a.txt").read_text() == text
    assert [p.name for p in tmp_path.iterdir()] == ["report"]


def test_no_module_renames_a_temporary_file_itself():
    """Every output file goes through write_atomic (streams that stay open while the run goes,
    the debug video, and the compiler's build folder keep their own rename)."""
    allowed = {"vehicle/userfiles.py", "trackgen/outdir.py", "simrunner/reports/video.py",
               "simrunner/run/native/build.py"}
    offenders = []
    for pkg in ("pieces", "vehicle", "worlds", "trackgen", "simrunner"):
        for path in (ROOT / pkg).rglob("*.py"):
            rel = path.relative_to(ROOT).as_posix()
            if rel in allowed:
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and \
                        node.func.attr in ("replace", "rename") and isinstance(node.func.value, ast.Name) \
                        and node.func.value.id == "os":
                    offenders.append(f"{rel}:{node.lineno}")
                if isinstance(node, ast.Attribute) and node.attr in ("mkstemp",):
                    offenders.append(f"{rel}:{node.lineno}")
    assert not offenders, offenders


def test_output_folders_get_the_permissions_mkdir_would_give(tmp_path):
    """Folders swapped in whole (gap, camera calibration, trackgen build) are readable by the
    team, as with mkdir: mkdtemp alone would leave them 0700."""
    import os

    from trackgen.outdir import make_temp, replace_folder

    mask = os.umask(0o022)
    try:
        tmp = make_temp(tmp_path / "out")
        (tmp / "a.txt").write_text("x")
        replace_folder(tmp, tmp_path / "out")
    finally:
        os.umask(mask)
    assert (tmp_path / "out").stat().st_mode & 0o777 == 0o755
