"""Bounded reading of the meshes a world places: triangles in the world frame, checked.

One reader for every consumer (``simrunner`` rasterises the triangles, ``trackgen validate``
measures them), so a damaged world gets the same one-line :class:`WorldError` from both.

:func:`read_triangles` reads one mesh file as ``(T, 3, 3)`` float64 triangles in the mesh
frame:

* binary STL (read directly with numpy): the file must be exactly ``84 + 50 T`` bytes for
  the ``T`` its header states (a truncated or padded file is refused, never read as part
  of a mesh); NXP's binary files that start with the word ``solid`` are binary by that test;
* ASCII STL (parsed here): ``facet normal / outer loop / 3 x vertex / endloop / endfacet``
  blocks closed by ``endsolid``; a file cut short (no ``endsolid``), a vertex that is not
  three numbers, or a facet without three vertices is refused at its line;
* any other suffix (``.dae``, ``.obj``, ``.ply``, ...) through trimesh, every failure of
  which becomes one line;

and refuses files over :data:`MAX_MESH_BYTES` (of what a compressed mesh, ``.stl.bz2``,
``.gz``, ``.xz`` or a ``.zip``, holds too: a zip's members as they inflate, not only as its
directory states them; a mesh compressed twice is refused), meshes with no triangles and
non-finite coordinates. :func:`scene_triangles` reads every visual and collision of a
``worlds.sdf_read.Scene`` (a file used twice is read once), applies ``<scale>`` and the
pose, and bounds the whole world: at most :data:`MAX_WORLD_TRIANGLES` triangles, all within
:data:`MAX_EXTENT_M` of each other in x and y (a raster of the track at 5 mm per pixel is
then at most 10,000 pixels a side).
"""
from __future__ import annotations

import bz2
import gzip
import lzma
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worlds.sdf_xml import WorldError

MAX_MESH_BYTES = 32 * 1024 * 1024  # one mesh file (NXP's are ~50 kB; 32 MiB of binary STL: 670,000 triangles)
MAX_WORLD_TRIANGLES = 4_000_000  # all meshes of a world together
MAX_EXTENT_M = 50.0  # x and y span of all meshes of a world (NXP's tracks: 7 m and 12 m)

_STL_HEADER_BYTES = 84
_COMPRESSED = {".bz2": bz2.open, ".gz": gzip.open, ".xz": lzma.open}  # a mesh compressed whole
_ZIP_PIECE_BYTES = 1 << 20  # a zip member is inflated at most this much at a time to check it
_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_VERTEX = re.compile(rf"^\s*vertex\s+({_NUMBER})\s+({_NUMBER})\s+({_NUMBER})\s*$", re.IGNORECASE)
_FACET = re.compile(rf"^\s*facet(?:\s+normal\s+{_NUMBER}\s+{_NUMBER}\s+{_NUMBER})?\s*$", re.IGNORECASE)


def read_triangles(path: str | Path) -> np.ndarray:
    """Triangles ``(T, 3, 3)`` float64 (metres, mesh frame) of one mesh file; WorldError
    (``file: message`` or ``file:line: message``) for anything the module docstring refuses."""
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise WorldError(f"{path}: cannot read mesh ({exc.strerror or exc})") from None
    if size > MAX_MESH_BYTES:
        raise WorldError(f"{path}: mesh file of {size / 2**20:.1f} MiB: at most "
                         f"{MAX_MESH_BYTES // 2**20} MiB are read")
    suffix = path.suffix.lower()
    if suffix in _COMPRESSED:
        tris = _read_compressed(path)
    elif suffix == ".stl":
        tris = _read_stl(path)
    else:
        if suffix == ".zip":
            _check_zip(path)
        tris = _read_other(path)
    if len(tris) == 0:
        raise WorldError(f"{path}: mesh has no triangles")
    if not np.isfinite(tris).all():
        raise WorldError(f"{path}: mesh has non-finite vertex coordinates (nan or inf)")
    return tris


def _read_stl(path: Path, data: bytes | None = None) -> np.ndarray:
    if data is None:
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise WorldError(f"{path}: cannot read mesh ({exc.strerror or exc})") from None
    if len(data) >= _STL_HEADER_BYTES:
        count = int.from_bytes(data[80:84], "little")
        if len(data) == _STL_HEADER_BYTES + 50 * count:
            records = np.frombuffer(data, dtype=_STL_RECORD, count=count, offset=_STL_HEADER_BYTES)
            return records["vertices"].astype(np.float64)
    if data.lstrip()[:5].lower() == b"solid" and _looks_like_text(data):
        return _read_ascii_stl(path, data)
    if len(data) < _STL_HEADER_BYTES:
        raise WorldError(f"{path}: not an STL file ({len(data)} bytes: shorter than a binary "
                         f"STL header and not ASCII STL)")
    expected = _STL_HEADER_BYTES + 50 * count
    what = "truncated" if len(data) < expected else "damaged"
    raise WorldError(f"{path}: {what} binary STL: its header states {count} triangles "
                     f"({expected} bytes) but the file has {len(data)} bytes")


def _looks_like_text(data: bytes) -> bool:
    """Mostly printable ASCII in the first 4 kB (NXP's binary files start with 80 bytes of
    text, then binary numbers)."""
    head = data[:4096]
    text = sum(1 for b in head if b in b"\t\n\r\f\v" or 32 <= b < 127)
    return text >= 0.95 * len(head)


def _read_ascii_stl(path: Path, data: bytes) -> np.ndarray:
    """Parse an ASCII STL strictly (module docstring); errors at their line."""
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise WorldError(f"{path}:{line}: ASCII STL has a non-ASCII byte") from None
    verts: list[tuple[float, float, float]] = []
    in_facet, facet_line, n_in_facet, ended = False, 0, 0, False
    started = False
    for lineno, raw in enumerate(text.splitlines(), start=1):
        words = raw.split()
        if not words:
            continue
        key = words[0].lower()
        if ended:
            raise WorldError(f"{path}:{lineno}: ASCII STL: text after 'endsolid'")
        if not started:  # the first line is 'solid [name]'
            started = True
            continue
        if key == "facet":
            if _FACET.match(raw) is None:
                raise WorldError(f"{path}:{lineno}: ASCII STL: expected 'facet normal NX NY NZ', "
                                 f"got {_quote(raw)}")
            if in_facet:
                raise WorldError(f"{path}:{lineno}: ASCII STL: 'facet' inside the facet of line {facet_line}")
            in_facet, facet_line, n_in_facet = True, lineno, 0
        elif key == "vertex":
            m = _VERTEX.match(raw)
            if not in_facet or m is None:
                raise WorldError(f"{path}:{lineno}: ASCII STL: expected 'vertex X Y Z' inside a facet, "
                                 f"got {_quote(raw)}")
            verts.append((float(m.group(1)), float(m.group(2)), float(m.group(3))))
            n_in_facet += 1
        elif key == "endfacet":
            if not in_facet or n_in_facet != 3:
                raise WorldError(f"{path}:{lineno}: ASCII STL: a facet needs exactly 3 vertices "
                                 f"(found {n_in_facet})")
            in_facet = False
        elif key == "endsolid":
            if in_facet:
                raise WorldError(f"{path}:{lineno}: ASCII STL: 'endsolid' inside the facet of line {facet_line}")
            ended = True
        elif key not in ("outer", "endloop"):
            raise WorldError(f"{path}:{lineno}: ASCII STL: unexpected {_quote(raw)}")
    if not ended:
        raise WorldError(f"{path}: truncated ASCII STL: no 'endsolid' at the end")
    return np.asarray(verts, dtype=np.float64).reshape(-1, 3, 3)


def _quote(text: str, limit: int = 40) -> str:
    text = text.strip()
    return repr(text if len(text) <= limit else text[:limit] + "...")


def _read_compressed(path: Path) -> np.ndarray:
    """A mesh compressed as a whole (``lane.stl.bz2``): decompressed up to MAX_MESH_BYTES (a
    small file can hold gigabytes: the limit holds for what it holds), then read as its inner
    suffix says."""
    opener = _COMPRESSED[path.suffix.lower()]
    try:
        with opener(path, "rb") as f:
            data = f.read(MAX_MESH_BYTES + 1)
    except (OSError, EOFError, ValueError) as exc:
        raise WorldError(f"{path}: cannot decompress mesh ({str(exc).splitlines()[0][:120] or type(exc).__name__})") from None
    if len(data) > MAX_MESH_BYTES:
        raise WorldError(f"{path}: compressed mesh holds more than {MAX_MESH_BYTES // 2**20} MiB: at most "
                         f"{MAX_MESH_BYTES // 2**20} MiB are read")
    inner = Path(path.stem)
    if inner.suffix.lower() == ".stl":
        return _read_stl(path, data)
    if inner.suffix.lower() in _COMPRESSED:
        raise WorldError(f"{path}: a mesh compressed twice ({inner.suffix} inside {path.suffix}): "
                         "expected one compression")
    import tempfile

    with tempfile.TemporaryDirectory(prefix="nxpcup-mesh-") as tmp:
        plain = Path(tmp) / inner.name
        plain.write_bytes(data)
        try:
            if inner.suffix.lower() == ".zip":  # a zip holds more than itself: its own limit
                _check_zip(plain)
            return _read_other(plain)
        except WorldError as exc:  # named as the world names it, not by the temporary copy
            raise WorldError(str(exc).replace(str(plain), str(path), 1)) from None


def _check_zip(path: Path) -> None:
    """A zip archive's members hold at most MAX_MESH_BYTES together: the sizes its directory
    states, checked before anything is inflated; then each member inflated in pieces of
    _ZIP_PIECE_BYTES up to one byte past its stated size (zipfile ends there with a CRC
    check), so a directory that understates a member - even with the CRC of the stated bytes
    - is refused in bounded memory before the mesh reader inflates it whole. Members are stored or deflated only: zipfile inflates a bzip2 or lzma member
    without a bound on one read (Python's zipfile.ZipExtFile._read1)."""
    import copy
    import zipfile
    import zlib

    try:
        with zipfile.ZipFile(path) as z:
            infos = z.infolist()
            total = sum(info.file_size for info in infos)
            if total > MAX_MESH_BYTES:
                raise WorldError(f"{path}: zip mesh holds {total / 2**20:.1f} MiB: at most "
                                 f"{MAX_MESH_BYTES // 2**20} MiB are read")
            for info in infos:
                if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                    method = zipfile.compressor_names.get(info.compress_type, f"method {info.compress_type}")
                    raise WorldError(f"{path}: zip mesh member {info.filename!r} is compressed with "
                                     f"{method}: expected deflate or stored (zip it again)")
                # read as stating one byte more than its directory does: a member that holds more
                # (its CRC may be forged to match the stated bytes, which zipfile would stop at and
                # accept, then inflate whole for the mesh reader) shows it in bounded memory
                probe = copy.copy(info)
                probe.file_size = info.file_size + 1
                inflated = 0
                with z.open(probe) as member:
                    while piece := member.read(_ZIP_PIECE_BYTES):
                        inflated += len(piece)
                if inflated > info.file_size:
                    raise WorldError(f"{path}: zip mesh member {info.filename!r} holds more than the "
                                     f"{info.file_size} bytes its directory states")
    except (OSError, EOFError, RuntimeError, zipfile.BadZipFile, zlib.error) as exc:  # RuntimeError: encrypted
        raise WorldError(f"{path}: cannot read zip mesh ({exc})") from None


def _read_other(path: Path) -> np.ndarray:
    try:
        import trimesh

        mesh = trimesh.load(str(path), force="mesh", process=False)
        faces = np.asarray(mesh.faces, dtype=np.int64)
        verts = np.asarray(mesh.vertices, dtype=np.float64)
    except Exception as exc:  # noqa: BLE001 - trimesh and its loaders raise many types
        reason = str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__
        raise WorldError(f"{path}: cannot read {path.suffix or 'suffix-less'} mesh ({reason})") from None
    if faces.ndim != 2 or faces.shape[1] != 3 or (len(faces) and (faces.min() < 0 or faces.max() >= len(verts))):
        raise WorldError(f"{path}: expected a triangle mesh")
    return verts[faces] if len(faces) else np.zeros((0, 3, 3))


# -- a whole scene -------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class SceneTriangles:
    """World-frame triangles ``(T, 3, 3)`` of each visual and collision of a scene, in the
    scene's order (read-only arrays)."""

    visuals: tuple[np.ndarray, ...]
    collisions: tuple[np.ndarray, ...]


def placed_triangles(tris: np.ndarray, world_from_mesh: np.ndarray, scale) -> np.ndarray:
    """Mesh-frame triangles ``(T, 3, 3)`` scaled (mesh frame) then moved by ``world_from_mesh (4, 4)``."""
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused by the caller
        verts = tris.reshape(-1, 3) * np.asarray(scale, dtype=float)
        tf = np.asarray(world_from_mesh, dtype=float)
        return (verts @ tf[:3, :3].T + tf[:3, 3]).reshape(-1, 3, 3)


def scene_triangles(scene) -> SceneTriangles:
    """Read every mesh of ``scene`` (a ``worlds.sdf_read.Scene``) within the module's limits."""
    files: dict[Path, np.ndarray] = {}
    total = 0
    lo = np.full(2, math.inf)
    hi = np.full(2, -math.inf)
    out: dict[str, list[np.ndarray]] = {"visuals": [], "collisions": []}
    for kind in ("visuals", "collisions"):
        for item in getattr(scene, kind):
            key = Path(item.mesh_path)
            if key not in files:
                files[key] = read_triangles(key)
            tris = placed_triangles(files[key], item.world_from_mesh, item.scale)
            total += len(tris)
            if total > MAX_WORLD_TRIANGLES:
                raise WorldError(f"{scene.source}: the world's meshes have more than "
                                 f"{MAX_WORLD_TRIANGLES:,} triangles (at {item.mesh_path})")
            if not np.isfinite(tris).all():
                raise WorldError(f"{item.mesh_path}: non-finite coordinates after <scale> and <pose> "
                                 f"of '{item.name}'")
            xy = tris[:, :, :2].reshape(-1, 2)
            tlo, thi = xy.min(axis=0), xy.max(axis=0)
            lo, hi = np.minimum(lo, tlo), np.maximum(hi, thi)
            span = hi - lo
            if (span > MAX_EXTENT_M).any():
                raise WorldError(
                    f"{item.mesh_path}: '{item.name}' makes the world's meshes span "
                    f"{span[0]:.4g} m x {span[1]:.4g} m in x, y (from ({lo[0]:.4g}, {lo[1]:.4g}) "
                    f"to ({hi[0]:.4g}, {hi[1]:.4g}) m); at most {MAX_EXTENT_M:g} m")
            tris.flags.writeable = False
            out[kind].append(tris)
    return SceneTriangles(tuple(out["visuals"]), tuple(out["collisions"]))


def upward(tris: np.ndarray, min_normal_z: float = 0.5) -> np.ndarray:
    """The triangles ``(T, 3, 3)`` whose unit normal has z > ``min_normal_z``."""
    if len(tris) == 0:
        return tris
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 0
    nz = np.zeros(len(n))
    nz[ok] = n[ok, 2] / norm[ok]
    return tris[nz > min_normal_z]
