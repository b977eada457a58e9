"""Read an SDF world (ours, NXP's or any Gazebo one) into a :class:`Scene` of mesh visuals.

``read_world(path)`` accepts

* a world file (``.sdf`` / ``.world``, SDF 1.4 and later) or a model file (``<sdf><model>``);
* a folder: ``world.sdf`` inside (trackgen output), else its single ``*.world`` file (or the
  one named like the folder; NXP's model folders ship one that places the track under a car
  at the origin), else its
  ``model.config`` (a Gazebo model folder; ``<sdf>`` names the model file).

``<include><uri>model://NAME</uri>`` is resolved by looking for a folder NAME (with a
``model.config``) in this order: the folder of the file being read and its parents
(the folder itself counts when it is named NAME), ``models/`` beside the world, then every
entry of ``GAZEBO_MODEL_PATH``, ``GZ_SIM_RESOURCE_PATH``, ``IGN_GAZEBO_RESOURCE_PATH`` and
``SDF_PATH``. ``model://ground_plane`` (Gazebo's stock model) is never looked up: it is the
ground at its include height. Mesh URIs may be ``model://NAME/...``, ``file://...``,
absolute, or relative to the file that contains them.

Poses (SDF: ``x y z roll pitch yaw``, ``R = Rz(yaw) Ry(pitch) Rx(roll)``) compose as
world_from_mesh = include/model pose @ link pose @ visual pose (nested models and includes
compose too). As in the SDF specification an include ``<pose>`` REPLACES the included
model's own top-level ``<pose>``. ``relative_to`` (SDF 1.7+) may name the model or a
sibling link only. Mesh ``<scale>`` is applied in the mesh frame, before world_from_mesh.

Files a world may read (``allowed_roots``): everything inside the world file's folder (for a
model folder: that folder) and inside the folders of the model path variables above,
compared after resolving ``..`` and symbolic links. A model, include or mesh URI that leads
anywhere else (``../x.stl``, ``model://name/../..``, ``model://..``, an absolute path, a link
out of the folder) is refused with a WorldError naming it; to read such files on purpose,
add their folder to ``GAZEBO_MODEL_PATH`` (documented in docs/worlds.md). ``model.config``'s
``<sdf>`` must name a file inside its own model folder.

Bounds (one WorldError each, never a RecursionError): an include that includes itself
(directly or through others), models nested more than :data:`MAX_MODEL_DEPTH` deep, more
than :data:`MAX_MODELS` models and includes in all; the XML limits of
:func:`worlds.sdf_xml.parse_xml`; and the mesh limits of :mod:`worlds.mesh_read`.

The car: a model named like the car (``nxp_cup_car`` by default) or holding a camera sensor
gives ``Scene.car_pose`` / ``car_z_m`` and contributes no visuals. Only ``<mesh>``
geometries become visuals (primitives are not track surfaces); a ``<plane>`` collision (or
the ``ground_plane`` include) gives ``ground_z_m``.
"""
from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pieces.pose import Pose2
from worlds.sdf_xml import WorldError, XmlDoc, parse_pose, parse_vector, parse_xml, text_of
from worlds.lighting import TrackLighting, from_sdf_world
from worlds.marks import Barcode
from worlds.marks import from_sdf_world as barcodes_of
from worlds.solids import from_sdf_world as solids_of

MODEL_PATH_ENV = ("GAZEBO_MODEL_PATH", "GZ_SIM_RESOURCE_PATH", "IGN_GAZEBO_RESOURCE_PATH", "SDF_PATH")
GROUND_MODELS = ("ground_plane",)
MAX_MODEL_DEPTH = 32  # <model>s and <include>s inside each other
MAX_MODELS = 10_000  # <model>s and <include>s read in all (an include counts each time)
DEFAULT_CAR_NAME = "nxp_cup_car"  # vehicle.description.CarDescription().name

# Gazebo's stock material scripts (media/materials/scripts/gazebo.material), diffuse RGBA.
GAZEBO_MATERIALS: dict[str, tuple[float, float, float, float]] = {
    "Gazebo/White": (1.0, 1.0, 1.0, 1.0),
    "Gazebo/WhiteGlow": (1.0, 1.0, 1.0, 1.0),
    "Gazebo/Black": (0.0, 0.0, 0.0, 1.0),
    "Gazebo/FlatBlack": (0.1, 0.1, 0.1, 1.0),
    "Gazebo/Grey": (0.7, 0.7, 0.7, 1.0),
    "Gazebo/Gray": (0.7, 0.7, 0.7, 1.0),
    "Gazebo/DarkGrey": (0.175, 0.175, 0.175, 1.0),
    "Gazebo/LightGrey": (0.9, 0.9, 0.9, 1.0),
    "Gazebo/Red": (1.0, 0.0, 0.0, 1.0),
    "Gazebo/Green": (0.0, 1.0, 0.0, 1.0),
    "Gazebo/Blue": (0.0, 0.0, 1.0, 1.0),
    "Gazebo/Yellow": (1.0, 1.0, 0.0, 1.0),
    "Gazebo/Orange": (1.0, 0.5088, 0.0468, 1.0),
    "Gazebo/Purple": (1.0, 0.0, 1.0, 1.0),
    "Gazebo/Turquoise": (0.0, 1.0, 1.0, 1.0),
}
_ROLE_WORDS = (("lane", ("lane", "inside")), ("edge", ("edge", "border")), ("marking", ("marking",)))


@dataclass(frozen=True, eq=False)
class MeshVisual:
    """One mesh visual or collision placed in the world.

    ``world_from_mesh`` is ``(4, 4)`` float (metres); ``scale`` ``(3,)`` is applied in the
    mesh frame first; ``rgba`` ``(4,)`` in 0..1 or None; ``role`` is "lane", "edge",
    "marking" or "other": from the element name (lane/inside, edge/border, marking), else
    from the colour (white-ish: lane, black-ish: edge).
    """

    name: str
    mesh_path: Path
    world_from_mesh: np.ndarray
    scale: np.ndarray
    rgba: np.ndarray | None
    material_name: str | None
    role: str = "other"


@dataclass(frozen=True, eq=False)
class Scene:
    """What the simulator needs from a world file (see the module docstring)."""

    source: Path
    visuals: tuple[MeshVisual, ...]
    collisions: tuple[MeshVisual, ...]
    car_pose: Pose2 | None
    car_z_m: float | None
    track_json: Path | None
    ground_z_m: float | None
    lighting: TrackLighting | None = None  # the world's lights (worlds.lighting), None: none
    barcodes: tuple[Barcode, ...] = ()      # printed barcodes (worlds.marks)
    boxes: tuple = ()                       # objects standing on the track (worlds.solids)


def read_world(path: str | Path, *, car_name: str = DEFAULT_CAR_NAME) -> Scene:
    """Read a world/model file or folder (see the module docstring); raises WorldError."""
    source = pick_file(Path(path))
    reader = _Reader(source, car_name)
    doc = parse_xml(source)
    reader.document(doc)
    track_json = source.parent / "track.json"
    if _is_file(track_json) and not inside(track_json, reader.roots):
        raise WorldError(f"{track_json}: links outside the world's folder {source.parent}")
    world = doc.root.find("world")
    lighting, barcodes, boxes = None, (), ()
    if world is not None:
        lighting = from_sdf_world(world, lambda el: tuple(parse_pose(doc, el.find("pose"))[:3, 3]))
        barcodes = barcodes_of(world)
        boxes = solids_of(world, str(source))
    return Scene(source=source, visuals=tuple(reader.visuals), collisions=tuple(reader.collisions),
                 car_pose=reader.car_pose, car_z_m=reader.car_z_m,
                 track_json=track_json if track_json.is_file() else None,
                 ground_z_m=reader.ground_z_m, lighting=lighting, barcodes=barcodes, boxes=boxes)


def load_mesh_world(visual: MeshVisual):
    """The visual's mesh as a ``trimesh.Trimesh`` with vertices ``(N, 3)`` in the world frame
    (read by :func:`worlds.mesh_read.read_triangles`: bounded, damaged files refused;
    three vertices per triangle, not merged)."""
    import trimesh

    from worlds.mesh_read import placed_triangles, read_triangles

    tris = placed_triangles(read_triangles(visual.mesh_path), visual.world_from_mesh, visual.scale)
    return trimesh.Trimesh(tris.reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3), process=False)


# -- files and models ----------------------------------------------------------------------
def _is_file(path: Path) -> bool:
    try:
        return path.is_file()
    except (OSError, ValueError):  # a name too long, a NUL byte
        return False


def _is_dir(path: Path) -> bool:
    try:
        return path.is_dir()
    except (OSError, ValueError):
        return False


def _resolved(path: Path) -> Path:
    try:
        return path.resolve()
    except (OSError, RuntimeError, ValueError):  # a symbolic-link loop, a name too long
        return path.absolute()


def model_path_dirs() -> list[Path]:
    """The folders of the model path variables (``MODEL_PATH_ENV``), in order."""
    return [Path(p) for var in MODEL_PATH_ENV for p in os.environ.get(var, "").split(os.pathsep) if p]


def allowed_roots(source: Path) -> tuple[Path, ...]:
    """Resolved folders whose files a world read from ``source`` may read (module docstring)."""
    roots = [_resolved(Path(source).parent), *(_resolved(d) for d in model_path_dirs())]
    return tuple(dict.fromkeys(roots))


def inside(path: Path, roots: tuple[Path, ...]) -> bool:
    """Whether ``path`` (resolved: ``..`` and links followed) lies in one of ``roots``."""
    p = _resolved(Path(path))
    return any(p == r or p.is_relative_to(r) for r in roots)


def _outside(path: Path, roots: tuple[Path, ...], what: str) -> str:
    return (f"{what} {path} is outside the world's folder {roots[0]} and the model path "
            f"(to allow it, add its folder to GAZEBO_MODEL_PATH)")


def pick_file(path: Path) -> Path:
    """The SDF file to read for ``path`` (a file, or a folder as in the module docstring)."""
    if _is_file(path):
        return path
    if not _is_dir(path):
        raise WorldError(f"{path}: world file or folder not found")
    if (path / "world.sdf").is_file():
        return path / "world.sdf"
    worlds = sorted(path.glob("*.world"))
    named = [w for w in worlds if w.stem == path.name]
    if len(worlds) == 1 or len(named) == 1:
        return worlds[0] if len(worlds) == 1 else named[0]
    if (path / "model.config").is_file():
        return model_file(path)
    if worlds:
        raise WorldError(f"{path}: several .world files ({', '.join(w.name for w in worlds)}); pass one")
    raise WorldError(f"{path}: expected world.sdf, one *.world file or model.config in the folder")


def model_file(model_dir: Path) -> Path:
    """The model SDF file of a Gazebo model folder (``model.config``'s ``<sdf>``, newest version)."""
    config = model_dir / "model.config"
    if not _is_file(config):
        if _is_file(model_dir / "model.sdf") and inside(model_dir / "model.sdf", (_resolved(model_dir),)):
            return model_dir / "model.sdf"
        raise WorldError(f"{model_dir}: model folder has no model.config")
    doc = parse_xml(config, "model.config")
    best: tuple[tuple[int, ...], ET.Element] | None = None
    for el in doc.root.findall("sdf"):
        try:
            version = tuple(int(p) for p in el.get("version", "0").split("."))
        except ValueError:
            raise doc.error(el, f"<sdf version='{el.get('version')}'>: expected a version like 1.6") from None
        if text_of(el) and (best is None or version > best[0]):
            best = (version, el)
    if best is None:
        raise doc.error(doc.root, "expected an <sdf> element naming the model file")
    path = model_dir / text_of(best[1])
    if not inside(path, (_resolved(model_dir),)):
        raise doc.error(best[1], f"<sdf>{text_of(best[1])}</sdf>: expected a file inside the model "
                        f"folder {model_dir}")
    if not _is_file(path):
        raise doc.error(best[1], f"model file {path.name} not found in {model_dir}")
    return path


def model_search_dirs(start_dirs: list[Path]) -> list[Path]:
    """Folders that may hold model folders, in search order (see the module docstring)."""
    out: list[Path] = []
    for start in start_dirs:
        start = start.resolve()
        for d in (start, *start.parents):
            out.append(d)
        out.append(start / "models")
    out += model_path_dirs()
    seen: set[Path] = set()
    return [d for d in out if not (d in seen or seen.add(d))]


def find_model(name: str, start_dirs: list[Path], roots: tuple[Path, ...] | None = None) -> Path | None:
    """Folder of model NAME, or None (a folder counts when it has a model.config/model.sdf).
    With ``roots``, only folders inside them count; a NAME that is not a plain folder name
    (empty, ``.``, ``..``, with a slash) is never found."""
    if name in ("", ".", "..") or "/" in name or "\\" in name:
        return None

    def is_model(d: Path) -> bool:
        return ((_is_file(d / "model.config") or _is_file(d / "model.sdf"))
                and (roots is None or inside(d, roots)))

    for d in model_search_dirs(start_dirs):
        if d.name == name and is_model(d):
            return d
        if is_model(d / name):
            return d / name
    return None


def _model_not_found(name: str, uri: str, start_dirs: list[Path]) -> str:
    if name in ("", ".", "..") or "/" in name or "\\" in name:
        return f"URI {uri}: '{name}' is not a model name (expected model://NAME/...)"
    outside = find_model(name, start_dirs)
    if outside is not None:
        return (f"model '{name}' of URI {uri} is only found at {outside}, outside the world's "
                f"folder and the model path (to allow it, add its folder to GAZEBO_MODEL_PATH)")
    return (f"model '{name}' not found (URI {uri}; searched the folders above the file, "
            f"models/ beside it, {', '.join(MODEL_PATH_ENV)})")


def resolve_uri(uri: str, doc: XmlDoc, el: ET.Element, start_dirs: list[Path],
                roots: tuple[Path, ...] | None = None) -> Path:
    """Absolute path of a mesh URI written in ``doc``; the file must exist and lie inside
    ``roots`` (default: :func:`allowed_roots` of the first of ``start_dirs``' files)."""
    roots = roots if roots is not None else allowed_roots(Path(start_dirs[0]) / "world.sdf")
    if uri.startswith("model://"):
        name, _, rest = uri[len("model://"):].partition("/")
        model_dir = find_model(name, [doc.path.parent, *start_dirs], roots)
        if model_dir is None:
            raise doc.error(el, _model_not_found(name, uri, [doc.path.parent, *start_dirs]))
        path = model_dir / rest
    elif uri.startswith("file://"):
        path = Path(uri[len("file://"):])
    elif "://" in uri:
        raise doc.error(el, f"URI {uri}: only model://, file:// and file paths are supported")
    else:
        path = Path(uri)
    if not path.is_absolute():
        path = doc.path.parent / path
    if not inside(path, roots):
        raise doc.error(el, _outside(path, roots, f"mesh URI {uri}: the file"))
    if not _is_file(path):
        raise doc.error(el, f"mesh file {path} not found (URI {uri})")
    return path


def _role(name: str, rgba: np.ndarray | None) -> str:
    low = name.lower()
    for role, words in _ROLE_WORDS:
        if any(w in low for w in words):
            return role
    if rgba is not None and float(np.min(rgba[:3])) >= 0.8:
        return "lane"  # white-ish
    if rgba is not None and float(np.max(rgba[:3])) <= 0.2:
        return "edge"  # black-ish
    return "other"


# -- the reader ----------------------------------------------------------------------------
class _Reader:
    def __init__(self, source: Path, car_name: str):
        self.start_dirs = [source.parent]
        self.roots = allowed_roots(source)
        self.including: list[Path] = [_resolved(source)]  # model files being read, outermost first
        self.n_models = 0
        self._docs: dict[Path, XmlDoc] = {}  # each model file parsed once per read
        self._found: dict[tuple[str, Path], Path | None] = {}  # find_model per (name, folder)
        self._model_files: dict[Path, tuple[Path, Path]] = {}  # model folder -> its file, resolved
        self.car_name = car_name
        self.visuals: list[MeshVisual] = []
        self.collisions: list[MeshVisual] = []
        self.car_pose: Pose2 | None = None
        self.car_z_m: float | None = None
        self.ground_z_m: float | None = None

    def document(self, doc: XmlDoc, world_from_parent: np.ndarray | None = None,
                 pose_override: np.ndarray | None = None, name: str | None = None,
                 depth: int = 0) -> None:
        root = doc.root
        if root.tag != "sdf":
            raise doc.error(root, f"expected <sdf> as the root element, found <{root.tag}>")
        included = world_from_parent is not None
        tf = world_from_parent if included else np.eye(4)
        world = root.find("world")
        models = root.findall("model")
        if world is not None and not included:
            for child in world:
                if child.tag == "model":
                    self.model(doc, child, tf, depth=depth)
                elif child.tag == "include":
                    self.include(doc, child, tf, depth)
        elif models:
            for model in models[:1] if included else models:  # an include names one model
                self.model(doc, model, tf, pose_override, name, depth)
        else:
            raise doc.error(root, "expected a <world> or <model> element under <sdf>")

    def _enter(self, doc: XmlDoc, el: ET.Element, depth: int) -> None:
        """Count one model or include; refuse too deep or too many."""
        self.n_models += 1
        if depth > MAX_MODEL_DEPTH:
            raise doc.error(el, f"models and includes nested more than {MAX_MODEL_DEPTH} deep")
        if self.n_models > MAX_MODELS:
            raise doc.error(el, f"more than {MAX_MODELS:,} models and includes in the world "
                            "(each include counted every time it is read)")

    def include(self, doc: XmlDoc, inc: ET.Element, parent_tf: np.ndarray, depth: int = 0) -> None:
        self._enter(doc, inc, depth)
        uri_el = inc.find("uri")
        uri = text_of(uri_el)
        if not uri:
            raise doc.error(inc, "<include> without a <uri>")
        pose_el = inc.find("pose")
        pose = parse_pose(doc, pose_el) if pose_el is not None else None
        name = text_of(inc.find("name")) or None
        target = uri[len("model://"):].rstrip("/") if uri.startswith("model://") else None
        if target in GROUND_MODELS:
            self._ground(parent_tf @ (pose if pose is not None else np.eye(4)))
            return
        if target is not None:
            key = (target, doc.path.parent)
            if key not in self._found:
                self._found[key] = find_model(target, [doc.path.parent, *self.start_dirs], self.roots)
            model_dir = self._found[key]
            if model_dir is None:
                raise doc.error(uri_el, _model_not_found(target, uri, [doc.path.parent, *self.start_dirs]))
        else:
            if "://" in uri and not uri.startswith("file://"):
                raise doc.error(uri_el, f"URI {uri}: only model://, file:// and folder paths are supported")
            model_dir = Path(uri[len("file://"):] if uri.startswith("file://") else uri)
            if not model_dir.is_absolute():
                model_dir = doc.path.parent / model_dir
            if not inside(model_dir, self.roots):
                raise doc.error(uri_el, _outside(model_dir, self.roots, f"include {uri}: the folder"))
            if not _is_dir(model_dir):
                raise doc.error(uri_el, f"included model folder {model_dir} not found")
        if model_dir not in self._model_files:
            path = model_file(model_dir)
            self._model_files[model_dir] = (path, _resolved(path))
        path, resolved = self._model_files[model_dir]
        if resolved in self.including:
            chain = " -> ".join(p.name if p.name not in ("model.sdf",) else f"{p.parent.name}/{p.name}"
                                for p in [*self.including[self.including.index(resolved):], resolved])
            raise doc.error(uri_el, f"include {uri} includes itself ({chain})")
        self.including.append(resolved)
        try:
            if resolved not in self._docs:
                self._docs[resolved] = parse_xml(path)
            self.document(self._docs[resolved], parent_tf, pose, name, depth)
        finally:
            self.including.pop()

    def model(self, doc: XmlDoc, el: ET.Element, parent_tf: np.ndarray,
              pose_override: np.ndarray | None = None, name: str | None = None,
              depth: int = 0) -> None:
        self._enter(doc, el, depth + 1)
        name = name or el.get("name", "")
        model_tf = parent_tf @ (pose_override if pose_override is not None
                                else parse_pose(doc, el.find("pose")))
        if name == self.car_name or any(s.get("type") in ("camera", "rgbd_camera", "depth_camera")
                                        for s in el.iter("sensor")):
            if self.car_pose is None:
                yaw = math.atan2(model_tf[1, 0], model_tf[0, 0])
                self.car_pose = Pose2(model_tf[0, 3], model_tf[1, 3], yaw)
                self.car_z_m = float(model_tf[2, 3])
            return
        if name in GROUND_MODELS:
            self._ground(model_tf)
        links = {link.get("name", ""): link for link in el.findall("link")}
        link_tfs: dict[str, np.ndarray] = {}

        def link_tf(link_name: str) -> np.ndarray:
            chain: list[str] = []  # links whose pose is relative to the next one (no recursion)
            while link_name not in link_tfs:
                pose_el = links[link_name].find("pose")
                rel = (pose_el.get("relative_to", "") if pose_el is not None else "").strip()
                chain.append(link_name)
                if rel in ("", "__model__", name):
                    link_tfs[link_name] = model_tf @ parse_pose(doc, pose_el)
                    chain.pop()
                    break
                if rel not in links or rel in chain:
                    some = ", ".join(list(links)[:5]) + (", ..." if len(links) > 5 else "")
                    raise doc.error(pose_el, f"<pose relative_to='{rel[:40]}'>: expected the model or "
                                    f"a sibling link ({some}), without a loop")
                link_name = rel
            for child in reversed(chain):
                pose_el = links[child].find("pose")
                parent = pose_el.get("relative_to", "").strip()
                link_tfs[child] = link_tfs[parent] @ parse_pose(doc, pose_el)
            return link_tfs[chain[0] if chain else link_name]

        for link_name, link in links.items():
            ltf = link_tf(link_name)
            for kind, out in (("visual", self.visuals), ("collision", self.collisions)):
                for item in link.findall(kind):
                    self.geometry(doc, item, ltf, link_name, out, kind == "collision")
        for child in el:
            if child.tag == "model":
                self.model(doc, child, model_tf, depth=depth + 1)
            elif child.tag == "include":
                self.include(doc, child, model_tf, depth + 1)

    def geometry(self, doc: XmlDoc, item: ET.Element, link_tf: np.ndarray, link_name: str,
                 out: list[MeshVisual], is_collision: bool) -> None:
        pose_el = item.find("pose")
        rel = (pose_el.get("relative_to", "") if pose_el is not None else "").strip()
        if rel not in ("", link_name):
            raise doc.error(pose_el, f"<pose relative_to='{rel}'>: expected the parent link '{link_name}'")
        tf = link_tf @ parse_pose(doc, pose_el)
        geom = item.find("geometry")
        if geom is None:
            raise doc.error(item, f"<{item.tag}> without <geometry>")
        if is_collision and geom.find("plane") is not None:
            self._ground(tf)
        mesh = geom.find("mesh")
        if mesh is None:
            return
        uri_el = mesh.find("uri")
        if not text_of(uri_el):
            raise doc.error(mesh, "<mesh> without a <uri>")
        path = resolve_uri(text_of(uri_el), doc, uri_el, self.start_dirs, self.roots)
        scale = parse_vector(doc, mesh.find("scale"), 3, (1.0, 1.0, 1.0), "3 numbers (scale x y z)")
        rgba, material_name = self.material(doc, item.find("material"))
        name = item.get("name", "")
        tf.setflags(write=False)
        scale.setflags(write=False)
        out.append(MeshVisual(name=name, mesh_path=path, world_from_mesh=tf, scale=scale, rgba=rgba,
                              material_name=material_name, role=_role(name, rgba)))

    @staticmethod
    def material(doc: XmlDoc, mat: ET.Element | None) -> tuple[np.ndarray | None, str | None]:
        if mat is None:
            return None, None
        script_name = text_of(mat.find("script/name")) or None
        rgba = None
        diffuse = mat.find("diffuse")
        if diffuse is not None and text_of(diffuse):
            values = parse_vector(doc, diffuse, len(text_of(diffuse).split()), (), "RGBA numbers")
            if len(values) not in (3, 4):
                raise doc.error(diffuse, f"<diffuse> '{text_of(diffuse)}' is not 3 or 4 numbers (RGBA)")
            rgba = np.append(values, 1.0) if len(values) == 3 else values
        elif script_name in GAZEBO_MATERIALS:
            rgba = np.array(GAZEBO_MATERIALS[script_name])
        if rgba is not None:
            rgba = np.clip(rgba, 0.0, 1.0)
            rgba.setflags(write=False)
        return rgba, script_name

    def _ground(self, tf: np.ndarray) -> None:
        if self.ground_z_m is None:
            self.ground_z_m = float(tf[2, 3])
