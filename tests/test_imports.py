"""What each package needs, and its one exception root.

The track tools (pieces, trackgen, worlds, vehicle) import and work without the simulator's
dependencies (dartpy, OpenCV, numba, scipy, tqdm): each check runs in a subprocess whose
``sys.meta_path`` refuses those modules, so this test process is not affected. The blocked
list is ``simrunner.cli.SIM_DEPENDENCIES``, checked against pyproject.toml here.
"""
from __future__ import annotations

import math
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from simrunner.cli import SIM_DEPENDENCIES

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())

# Prepended to every subprocess script: ``import X`` of a blocked name fails as if X were not
# installed (ModuleNotFoundError with ``.name``, what Python raises for a missing module).
BLOCKER = """
import sys

class _NotInstalled:
    def __init__(self, names):
        self.names = frozenset(names)

    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in self.names:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None

sys.meta_path.insert(0, _NotInstalled(%r))
"""


def run_blocked(script: str, blocked, *, timeout_s: float = 300.0) -> subprocess.CompletedProcess:
    """Run ``script`` in a fresh interpreter (cwd: the repository) with ``blocked`` unimportable."""
    code = BLOCKER % (sorted(blocked),) + script
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout_s)


def _name(requirement: str) -> str:
    """Distribution name of a PEP 508 requirement string (``"numpy>=1.26"`` -> ``"numpy"``)."""
    for i, ch in enumerate(requirement):
        if ch in "<>=!~;[ (":
            return requirement[:i].strip().lower()
    return requirement.strip().lower()


# ------------------------------------------------------------------------ pyproject.toml
def test_pyproject_dependencies_track_group_and_python_floor():
    project = PYPROJECT["project"]
    deps = project["dependencies"]
    track = PYPROJECT["dependency-groups"]["track"]
    # vehicle/userfiles.py imports tomllib and simrunner uses enum.StrEnum: Python 3.11
    assert project["requires-python"] == ">=3.11"
    assert all(">=" in d for d in deps), "every dependency has a lower bound"
    # the group is the track tools' part of `dependencies`, verbatim
    assert set(track) <= set(deps)
    # the rest is exactly the simulator's table of one-line errors
    sim_only = {_name(d) for d in deps} - {_name(d) for d in track}
    assert sim_only == set(SIM_DEPENDENCIES.values())
    # a plain install still gets everything (the README quick start)
    assert {"dartpy", "opencv-python-headless", "numba"} <= {_name(d) for d in deps}


# ------------------------------------------------------ the track tools, simulator blocked
TRACK_TOOLS_SCRIPT = """
import math
from pathlib import Path

import pieces, trackgen, vehicle, worlds
from trackgen import TrackGenerator, validate_path
from trackgen.build import build
from trackgen.validate import errors
from vehicle import CarDescription, load_car
from worlds import load_mesh_world, read_world

out = Path(%r)
layout = out / "oval.txt"
layout.write_text("@name = oval\\nSTART_FINISH\\nSTRAIGHT\\nTURN_LEFT angle=90 x2\\n"
                  "STRAIGHT x2\\nTURN_LEFT angle=90 x2\\n")
result = build(layout, out / "oval")          # STL, SDF, JSON and preview.png (matplotlib)
assert result.preview_path.stat().st_size > 1000
assert errors(validate_path(out / "oval")) == []
scene = read_world(out / "oval")
assert len(scene.visuals) >= 3
assert all(len(load_mesh_world(v).faces) > 0 for v in scene.visuals)
track = TrackGenerator().add_piece(pieces.TURN_LEFT, angle_deg=90, radius_m=0.6).build()
assert abs(track.end_pose.yaw_rad - math.pi / 2) < 1e-12
car = load_car()
car.save(out / "car.toml")                    # tomli_w out, tomllib in
assert load_car(out / "car.toml") == car == CarDescription()
blocked = sorted(m for m in sys.modules if m.partition(".")[0] in %r)
print("OK", blocked)
"""


def test_track_tools_work_without_the_simulator_dependencies(tmp_path):
    blocked = set(SIM_DEPENDENCIES)
    proc = run_blocked(TRACK_TOOLS_SCRIPT % (str(tmp_path), sorted(blocked)), blocked)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "OK []"


def test_trackgen_cli_without_the_simulator_dependencies(tmp_path):
    script = (f"from trackgen.cli import main; sys.argv = ['trackgen', 'build', "
              f"{str(ROOT / 'examples' / 'oval_start.txt')!r}, '-o', {str(tmp_path / 'o')!r}]; main()")
    proc = run_blocked(script, SIM_DEPENDENCIES)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "o" / "world.sdf").is_file() and (tmp_path / "o" / "preview.png").is_file()


# --------------------------------------------- simrunner: a missing dependency is one line
@pytest.mark.parametrize("module", ["dartpy", "cv2"])
def test_simrunner_drive_without_a_dependency_says_so_in_one_line(module):
    script = ("from simrunner.cli import main; sys.argv = ['simrunner', 'drive', "
              "'examples/line_follower.py', '--time-limit', '0.05']; main()")
    proc = run_blocked(script, {module})
    dist = SIM_DEPENDENCIES[module]
    what = dist if dist == module else f"{dist} (module {module})"
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == (f"simrunner: the simulator needs {what}, which is not installed: "
                           f"pip install {dist}\n")
    assert proc.stdout == ""


def test_simrunner_drive_does_not_load_numba():
    """The camera line is NumPy (simrunner.sensors.line_row): drive runs with numba blocked,
    so its ~0.5 s load is not in any run's start-up."""
    script = ("from simrunner.cli import main; sys.argv = ['simrunner', 'drive', "
              "'examples/line_follower.py', '--time-limit', '0.05']; main()")
    proc = run_blocked(script, {"numba", "llvmlite", "scipy"})
    assert proc.returncode == 1, proc.stderr  # the time limit: a failed run, not bad input
    assert proc.stdout.startswith("outcome: timeout") and proc.stderr == ""


def test_simrunner_batch_loads_neither_numba_nor_tqdm_without_a_terminal(tmp_path):
    """The batch's process and its forked workers run with numba blocked (no run uses it,
    ~0.16 s of the command's start-up) and, stderr not being a terminal (no progress bar is
    shown there), with tqdm blocked (~20 ms)."""
    script = ("from simrunner.cli import main; sys.argv = ['simrunner', 'batch', "
              f"'examples/line_follower.py', '--seeds', '2', '--workers', '1', '--time-limit', '0.05', "
              f"'--no-plot', '-o', {str(tmp_path / 'out')!r}]; main()")
    proc = run_blocked(script, {"numba", "llvmlite", "scipy", "tqdm"})
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("2 runs on 1 worker(s) (local)") and "timeout 2" in proc.stdout
    assert proc.stderr == ""


def test_simrunner_help_without_the_simulator_dependencies():
    proc = run_blocked("from simrunner.cli import main; sys.argv = ['simrunner', '--help']; main()",
                       SIM_DEPENDENCIES)
    assert proc.returncode == 0, proc.stderr
    assert all(cmd in proc.stdout for cmd in ("drive", "calibrate", "excite", "gap"))


# --------------------------------------------------------------- one root per package
def test_one_exception_root_per_package():
    import pieces
    import simrunner
    import trackgen
    import vehicle
    import worlds
    from simrunner.errors import CameraError, CommandError, ControllerError, ControllerFileError
    from simrunner.workflows.gap import GapError, LogError
    from trackgen.build import OutputError, ValidationFailed

    roots = [pieces.PieceError, trackgen.TrackError, worlds.WorldError,
             vehicle.CarDescriptionError, simrunner.SimError]
    for a in roots:  # no root is under another
        assert not any(a is not b and issubclass(a, b) for b in roots)
    for sub in (trackgen.LayoutError, ValidationFailed, OutputError):
        assert issubclass(sub, trackgen.TrackError)
    for sub in (CameraError, CommandError, ControllerError, ControllerFileError, GapError, LogError):
        assert issubclass(sub, simrunner.SimError)


def test_track_generator_settings_of_the_wrong_type_is_a_layout_error():
    from trackgen import LayoutError, TrackGenerator

    with pytest.raises(LayoutError, match=r"TrackGenerator\(settings=\{'lane_width_m': 1\}\): "
                                          r"expected a pieces.TrackSettings") as info:
        TrackGenerator({"lane_width_m": 1})
    assert info.value.path == __file__
    with pytest.raises(LayoutError, match=r"TrackGenerator\(name=3\): expected a string"):
        TrackGenerator(name=3)


@pytest.mark.parametrize("text,message", [
    ("0 0 0 0 0 0 0", "the quaternion qx qy qz qw is zero"),
    ("0 0 0 0 0 1", "is not 7 finite numbers"),
    ("0 0 0 0 0 nan 1", "is not 7 finite numbers"),
])
def test_bad_quaternion_pose_is_a_world_error(text, message):
    from worlds.sdf_xml import WorldError, XmlDoc, parse_pose

    el = ET.Element("pose", {"rotation_format": "quat_xyzw"})
    el.text = text
    doc = XmlDoc(Path("w.sdf"), el, {el: 4})
    with pytest.raises(WorldError, match=rf"^w\.sdf:4: <pose> '{text}'.*{message}"):
        parse_pose(doc, el)


def test_quaternion_pose_tiny_and_empty():
    from worlds.sdf_xml import XmlDoc, parse_pose

    el = ET.Element("pose", {"rotation_format": "quat_xyzw"})
    doc = XmlDoc(Path("w.sdf"), el, {})
    el.text = "1 2 3 0 0 1e-200 1e-200"  # a quarter turn about z; no underflow to zero
    m = parse_pose(doc, el)
    assert m[:3, 3].tolist() == [1.0, 2.0, 3.0]
    assert math.isclose(m[1, 0], 1.0) and abs(m[0, 0]) < 1e-15
    el.text = ""
    assert np.array_equal(parse_pose(doc, el), np.eye(4))


def test_camera_supersample_below_one_is_a_camera_error():
    from simrunner.errors import CameraError
    from simrunner.sensors.camera import Camera
    from vehicle.description import Camera as CameraSpec

    with pytest.raises(CameraError, match="supersample must be >= 1, got 0"):
        Camera(CameraSpec(), None, supersample=0)
