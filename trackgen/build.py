"""``trackgen build`` and ``trackgen validate`` as library functions.

:func:`check_layout` chains and validates a layout; :func:`build` refuses a failing layout
(:class:`ValidationFailed`, nothing written) and otherwise writes the output folder of
docs/DESIGN.md ("Track output folder") atomically: everything goes into a temporary folder
beside ``out_dir`` that is renamed into place at the end, so a failed build leaves no
``out_dir`` (and an existing one is only replaced with ``force=True``, swapped atomically:
``out_dir`` always holds a complete build). Temporary folders of killed builds are removed
by the next build of the same ``out_dir`` (:mod:`trackgen.outdir`).
"""
from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from vehicle.description import CarDescription
from worlds.sdf_xml import WorldError

from .chain import Track, chain
from .errors import TrackError
from .export import TrackGeometry, dumps_track_json, track_geometry, track_json
from .layout import Layout, load_layout
from .outdir import clean_stale, make_temp, replace_folder
from .validate import HillLimits, Problem, check_meshes, count_errors, errors, summarise, validate_track

WORLD_SUFFIXES = (".sdf", ".world")

TRACK_JSON_KEYS = ("format", "name", "layout", "settings", "pieces", "start_pose",
                   "finish_gate", "centreline", "length_m", "surface_z_m", "lane_polygon",
                   "road_polygon")
"""The fields every track.json has (``trackgen validate`` reports the missing ones)."""
OPTIONAL_TRACK_JSON_KEYS = ("course",)
"""Fields newer builds write (a folder built before them still validates and drives)."""


class ValidationFailed(TrackError):
    """The layout has problems; ``problems`` lists them all (warnings included)."""

    def __init__(self, problems: list[Problem]) -> None:
        self.problems = list(problems)
        errs = errors(self.problems)
        count = count_errors(self.problems)
        more = f" (and {count - 1} more)" if count > 1 else ""
        super().__init__(f"{errs[0]}{more}" if errs else "validation failed")


class OutputError(TrackError):
    """The output folder cannot be written (exists without force, permissions, disk)."""


@dataclass(frozen=True, eq=False)
class Checked:
    """A chained, validated layout: ``track``, its world ``geometry`` (the footprint unions,
    made on first use when the checks did not need them) and ``problems``."""

    track: Track
    _geometry: TrackGeometry | None
    problems: list[Problem]

    @property
    def geometry(self) -> TrackGeometry:
        if self._geometry is None:
            object.__setattr__(self, "_geometry", track_geometry(self.track))
        return self._geometry

    @property
    def ok(self) -> bool:
        return not errors(self.problems)


@dataclass(frozen=True)
class BuildResult:
    """Paths written by :func:`build` and the warnings that did not stop it."""

    out_dir: Path
    world_path: Path
    track_json_path: Path
    preview_path: Path | None
    preview_size_px: tuple[int, int] | None
    warnings: list[Problem]


def check_layout(layout: Layout, car: CarDescription | None = None, *,
                 meshes: bool = True) -> Checked:
    """Chain ``layout`` and run every check of :mod:`trackgen.validate`; ``meshes=False``
    skips the mesh check (and with it manifold3d). The footprint unions and the mesh check
    run only when the other checks pass: overlapping pieces make unions slow (a layout of
    10 000 pieces on one circle) and a failing layout is not built anyway."""
    car = car or CarDescription()
    track = chain(layout)
    problems = validate_track(track, car.min_turn_radius_m, hill_limits=HillLimits.of_car(car),
                              car_width_m=car.chassis.track_m + car.wheels.width_m)
    if errors(problems) or not meshes:
        return Checked(track, None, problems)
    geometry = track_geometry(track)
    first_line = track.passes[0].line
    found = [Problem(layout.path, first_line, msg, "mesh") for msg in check_meshes(geometry.meshes)]
    if found:
        problems = summarise(sorted(problems + found, key=lambda p: (p.line or 0)), layout.path)
    return Checked(track, geometry, problems)


def check_buildable(layout: Layout, car: CarDescription | None = None, *,
                    meshes: bool = True) -> Checked:
    """:func:`check_layout`, raising what :func:`build` raises for a layout it refuses:
    :class:`TrackError` (the track is named like the car model) or :class:`ValidationFailed`.
    ``meshes=False``: for a user of the 2D geometry only (the simulator's in-memory track),
    without the mesh check."""
    car = car or CarDescription()
    if layout.name == car.name:
        raise TrackError(f"{layout.path}: track name {layout.name!r} equals the car model "
                         "name; choose another with '@name = ...'")
    checked = check_layout(layout, car, meshes=meshes)
    if not checked.ok:
        raise ValidationFailed(checked.problems)
    return checked


def build(layout: str | Path | Layout, out_dir: str | Path, *, force: bool = False,
          car: CarDescription | None = None, preview: bool = True) -> BuildResult:
    """Validate and write the output folder (``preview=False`` skips preview.png and
    matplotlib). Raises :class:`LayoutError` (bad layout),
    :class:`ValidationFailed` (problems; nothing written), :class:`OutputError` (cannot
    write; nothing left behind), :class:`TrackError` (the SDF layer refused)."""
    car = car or CarDescription()
    if not isinstance(layout, Layout):
        layout = load_layout(layout)
    out_dir = Path(out_dir)
    _check_target(out_dir, force)
    checked = check_buildable(layout, car)
    try:
        out_dir.parent.mkdir(parents=True, exist_ok=True)
        clean_stale(out_dir)
        tmp = make_temp(out_dir)
    except OSError as exc:
        raise OutputError(f"{out_dir}: cannot write output folder ({exc.strerror or exc})") from None
    try:
        size = _write_all(tmp, checked, car, preview)
        _move_into_place(tmp, out_dir, force)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise OutputError(f"{out_dir}: cannot write output folder ({exc.strerror or exc})") from None
    except WorldError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise TrackError(f"{layout.path}: cannot write the world: {exc}") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return BuildResult(out_dir, out_dir / "world.sdf", out_dir / "track.json",
                       out_dir / "preview.png" if preview else None, size, checked.problems)


def _check_target(out_dir: Path, force: bool) -> None:
    if out_dir.exists() or out_dir.is_symlink():
        if not out_dir.is_dir() or out_dir.is_symlink():
            raise OutputError(f"{out_dir}: exists and is not a folder; choose another output")
        if not force:
            raise OutputError(f"{out_dir}: already exists (use --force to replace it)")


def _write_all(tmp: Path, checked: Checked, car: CarDescription,
               preview: bool) -> tuple[int, int] | None:
    from worlds.sdf_write import write_track_world
    track, geometry = checked.track, checked.geometry
    name = track.layout.name
    mesh_dir = tmp / "models" / name / "meshes"
    mesh_dir.mkdir(parents=True)
    rel = {}
    for role, mesh in geometry.meshes.items():
        mesh.export(mesh_dir / f"{role}.stl", file_type="stl")
        rel[role] = f"meshes/{role}.stl"
    write_track_world(tmp, track_name=name, meshes=rel, start_pose=track.car_start_pose(),
                      surface_z_m=track.layout.settings.thickness_m, car=car,
                      lighting=track.lighting(), barcodes=track.layout.barcodes, tunnels=track.tunnels(),
                      boxes=track.layout.boxes)
    (tmp / "track.json").write_text(dumps_track_json(track_json(track, geometry)))
    if not preview:
        return None
    from .preview import render_preview  # matplotlib: only when a preview is wanted

    return render_preview(track, geometry, tmp / "preview.png")


def _move_into_place(tmp: Path, out_dir: Path, force: bool) -> None:
    if out_dir.exists():
        if not force:  # appeared while we were building
            raise OutputError(f"{out_dir}: already exists (use --force to replace it)")
    replace_folder(tmp, out_dir)


# -- validate PATH ---------------------------------------------------------------------------
def validate_path(path: str | Path, car: CarDescription | None = None, *,
                  sdf_checker: bool = True) -> list[Problem]:
    """Problems of a layout file, or of a build folder (its track.json's layout re-checked
    if it can be found, plus the folder's meshes, track.json fields and world files).
    Raises :class:`LayoutError` / :class:`TrackError` for unreadable input."""
    from .world_check import validate_world

    path = Path(path)
    if path.is_dir() and not (path / "track.json").is_file() or path.suffix.lower() in WORLD_SUFFIXES:
        return validate_world(path, car, sdf_checker=sdf_checker)
    if not path.is_dir():
        return check_layout(load_layout(path), car).problems
    return _validate_folder(path, car, sdf_checker)


def _validate_folder(folder: Path, car: CarDescription | None, sdf_checker: bool) -> list[Problem]:
    from worlds.track_json import load_json

    from .world_check import read_world_road

    world = read_world_road(folder)  # as the simulator reads it: its errors, in its order
    tj = folder / "track.json"
    doc = load_json(tj)
    problems: list[Problem] = world.start_problems()
    missing = [k for k in TRACK_JSON_KEYS if k not in doc]
    if missing:
        problems.append(Problem(str(tj), None, f"missing fields: {', '.join(missing)}", "folder"))
    problems += _recorded_layout_problems(doc.get("layout"), folder, tj, car)
    name = str(doc.get("name", ""))
    mesh_dir = folder / "models" / name / "meshes"
    import warnings

    import numpy as np
    import trimesh  # ~0.5 s (scipy): only when a folder's meshes are checked

    from worlds.mesh_read import read_triangles

    meshes = {}
    from worlds.sdf_read import inside

    roles = ("lane", "edges", "markings", "hill_lane", "hill_edges")  # the last three only if any
    if not name or not inside(mesh_dir, (folder.resolve(),)):
        problems.append(Problem(str(tj), None, f"name {name[:40]!r}: expected the track model's "
                                "folder name (models/NAME inside the folder)", "folder"))
        roles = ()
    for role in roles:
        f = mesh_dir / f"{role}.stl"
        if not f.is_file():
            if role in ("lane", "edges"):
                problems.append(Problem(str(f), None, f"{role} mesh missing", "mesh"))
            continue
        try:  # bounded and strict (worlds.mesh_read); vertices merged as trimesh.load does
            tris = read_triangles(f)
        except WorldError as exc:
            problems.append(Problem(str(f), None, str(exc).split(": ", 1)[-1], "mesh"))
            continue
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            meshes[role] = trimesh.Trimesh(tris.reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3))
    with warnings.catch_warnings(), np.errstate(all="ignore"):  # far vertices: checked, not warned
        warnings.simplefilter("ignore")
        mesh_messages = check_meshes(meshes)
    for msg in mesh_messages:
        role = msg.split(" ", 1)[0]
        problems.append(Problem(str(mesh_dir / f"{role}.stl"), None, msg, "mesh"))
    world = folder / "world.sdf"
    if not world.is_file():
        problems.append(Problem(str(world), None, "world.sdf missing", "folder"))
    else:
        from worlds.check import check_world

        problems += [Problem(str(world), None, msg, "folder")
                     for msg in check_world(world, use_ign=sdf_checker)]
    return problems


def _recorded_layout_problems(recorded, folder: Path, tj: Path,
                              car: CarDescription | None) -> list[Problem]:
    """Re-check the layout track.json names, if it is a layout file (``.txt``) in the folder,
    beside it or under the working directory; its contents are never echoed from anywhere
    else (a tampered ``"layout": "/etc/passwd"`` is not read)."""
    from .layout import LayoutError

    if not isinstance(recorded, str) or not recorded:
        return [Problem(str(tj), None, "layout: expected the path of the layout file", "folder",
                        warning=True)]
    shown = recorded if len(recorded) <= 80 else recorded[:77] + "..."
    found, refused = _find_layout(recorded, folder)
    if found is None:
        why = (f"not read: {refused}" if refused else
               "not found beside the folder or under the working directory")
        return [Problem(str(tj), None, f"layout {shown!r} {why}; the layout was not re-checked",
                        "folder", warning=True)]
    try:
        layout = load_layout(found)
    except LayoutError as exc:
        at = f" (line {exc.line})" if exc.line else ""
        return [Problem(str(tj), None, (
            f"layout {shown!r} does not load{at}; run 'trackgen validate {found}' for details"),
            "folder")]
    return check_layout(layout, car).problems


def _find_layout(recorded: str, folder: Path) -> tuple[Path | None, str | None]:
    """The layout file track.json names and None, or None and why it is refused."""
    from worlds.sdf_read import inside

    p = Path(recorded)
    cands = [p] if p.is_absolute() else [p, folder / p, folder.parent / p]
    roots = tuple(d.resolve() for d in (folder, folder.parent, Path.cwd()))
    refused = None
    for cand in cands:
        try:
            if not cand.is_file():
                continue
        except (OSError, ValueError):
            continue
        if cand.suffix.lower() != ".txt":
            refused = "not a layout file (.txt)"
        elif not inside(cand, roots):
            refused = "outside the folder, its parent folder and the working directory"
        else:
            return cand, None
    return None, refused
