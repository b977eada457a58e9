"""XML plumbing shared by the SDF writer, reader and checker.

* :class:`WorldError` - the one exception of the SDF layer; its message is one line that
  starts with ``file:line:`` (or ``file:`` when no line is known).
* :func:`parse_xml` - ElementTree parsing that remembers the source line of every element
  (expat + ``ElementTree.TreeBuilder``; plain ElementTree forgets lines).
* SDF poses: ``x y z roll pitch yaw`` (metres, radians), rotation extrinsic X-Y-Z, i.e.
  ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``; :func:`pose_matrix` gives the ``(4, 4)``
  homogeneous transform parent_from_child.
* :func:`sub` and :func:`write_xml` build and atomically write pretty-printed XML.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

import numpy as np

from vehicle.userfiles import write_atomic

SDF_VERSION = "1.6"  # dartpy's SdfParser reads 1.4-1.6 only; Gazebo reads 1.6
MAX_XML_BYTES = 16 * 1024 * 1024  # one SDF / model.config file (NXP's are ~2 kB)
MAX_XML_DEPTH = 100  # element nesting (an SDF world nests about 10 deep)


class WorldError(ValueError):
    """A world, model or mesh file is missing or malformed (one-line message)."""


@dataclass(frozen=True, eq=False)
class XmlDoc:
    """A parsed XML file: ``root`` element and the source line of each element."""

    path: Path
    root: ET.Element
    lines: dict = field(repr=False)

    def where(self, el: ET.Element | None = None) -> str:
        """``"path:line"`` of an element (``"path"`` when unknown)."""
        line = self.lines.get(el) if el is not None else None
        return f"{self.path}:{line}" if line else str(self.path)

    def error(self, el: ET.Element | None, message: str) -> WorldError:
        return WorldError(f"{self.where(el)}: {message}")


def parse_xml(path: Path, what: str = "SDF file") -> XmlDoc:
    """Parse ``path``; a missing/unreadable file or bad XML raises :class:`WorldError`.

    Bounded: files over :data:`MAX_XML_BYTES`, elements nested over :data:`MAX_XML_DEPTH`
    deep and any ``<!DOCTYPE>`` (entity declarations: "billion laughs"; SDF uses none) are
    refused."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_XML_BYTES:
            raise WorldError(f"{path}: {what} of {size / 2**20:.1f} MiB: at most "
                             f"{MAX_XML_BYTES // 2**20} MiB are read")
        data = path.read_bytes()
    except FileNotFoundError:
        raise WorldError(f"{path}: {what} not found") from None
    except OSError as exc:
        raise WorldError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    builder = ET.TreeBuilder()
    parser = expat.ParserCreate()
    lines: dict = {}
    depth = [0]

    def start(tag, attrs):
        depth[0] += 1
        if depth[0] > MAX_XML_DEPTH:
            raise WorldError(f"{path}:{parser.CurrentLineNumber}: elements nested more than "
                             f"{MAX_XML_DEPTH} deep in {what}")
        lines[builder.start(tag, attrs)] = parser.CurrentLineNumber

    def end(tag):
        depth[0] -= 1
        builder.end(tag)

    def doctype(*_args):
        raise WorldError(f"{path}:{parser.CurrentLineNumber}: <!DOCTYPE> in {what}: SDF files "
                         "have none (entity declarations are not read)")

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = builder.data
    parser.StartDoctypeDeclHandler = doctype
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise WorldError(f"{path}:{exc.lineno}: invalid XML in {what}: "
                         f"{expat.ErrorString(exc.code)} (column {exc.offset + 1})") from None
    return XmlDoc(path, builder.close(), lines)


def text_of(el: ET.Element | None, default: str = "") -> str:
    """Stripped text of an element; ``default`` when the element or its text is missing."""
    if el is None or el.text is None:
        return default
    return el.text.strip()


# -- poses ---------------------------------------------------------------------------------
def rotation_rpy(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """``(3, 3)`` rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (SDF convention)."""
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def pose_matrix(x=0.0, y=0.0, z=0.0, roll=0.0, pitch=0.0, yaw=0.0) -> np.ndarray:
    """``(4, 4)`` homogeneous transform of an SDF pose (metres, radians)."""
    m = np.eye(4)
    m[:3, :3] = rotation_rpy(roll, pitch, yaw)
    m[:3, 3] = (x, y, z)
    return m


def _quat_matrix(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    """``(3, 3)`` rotation of a non-zero quaternion (normalised here)."""
    n = math.hypot(qx, qy, qz, qw)  # no underflow for tiny components
    x, y, z, w = qx / n, qy / n, qz / n, qw / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _finite_numbers(text: str, n: int) -> list[float] | None:
    """The ``n`` finite numbers of ``text`` ("a b c"); None when it is anything else."""
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        return None
    if len(values) != n or not all(math.isfinite(v) for v in values):
        return None
    return values


def parse_pose(doc: XmlDoc, el: ET.Element | None) -> np.ndarray:
    """``(4, 4)`` transform of a ``<pose>`` element; identity when ``el`` is None or empty.

    Accepts ``x y z roll pitch yaw`` (radians; degrees with ``degrees="true"``) and, with
    ``rotation_format="quat_xyzw"``, ``x y z qx qy qz qw``. Anything else raises
    :class:`WorldError` at the element's line.
    """
    text = text_of(el)
    if not text:
        return np.eye(4)
    quat = el.get("rotation_format", "euler_rpy") == "quat_xyzw"
    want = 7 if quat else 6
    values = _finite_numbers(text, want)
    if values is None:
        form = "x y z qx qy qz qw" if quat else "x y z roll pitch yaw"
        raise doc.error(el, f"<pose> '{text}' is not {want} finite numbers ({form})")
    if quat:
        if math.hypot(*values[3:]) == 0.0:
            raise doc.error(el, f"<pose> '{text}': the quaternion qx qy qz qw is zero")
        m = np.eye(4)
        m[:3, :3] = _quat_matrix(*values[3:])
        m[:3, 3] = values[:3]
        return m
    if el.get("degrees", "false").strip().lower() in ("true", "1"):
        values[3:] = [math.radians(v) for v in values[3:]]
    return pose_matrix(*values)


def parse_vector(doc: XmlDoc, el: ET.Element | None, n: int, default: tuple[float, ...],
                 what: str) -> np.ndarray:
    """``(n,)`` float array from an element's text ("a b c"); ``default`` when absent.
    Anything but ``n`` finite numbers raises :class:`WorldError` at the element's line."""
    if el is None or not text_of(el):
        return np.array(default, dtype=float)
    values = _finite_numbers(text_of(el), n)
    if values is None:
        raise doc.error(el, f"<{el.tag}> '{text_of(el)}' is not {what}")
    return np.array(values, dtype=float)


def fmt(*values: float) -> str:
    """Space-separated numbers, shortest round-trip repr; whole numbers without ``.0``."""
    out = []
    for v in values:
        v = float(v) + 0.0  # turns -0.0 into 0.0
        out.append(str(int(v)) if v.is_integer() and abs(v) < 1e15 else repr(v))
    return " ".join(out)


# -- writing -------------------------------------------------------------------------------
def sub(parent: ET.Element, tag: str, text: str | float | int | bool | None = None,
        **attrs: str) -> ET.Element:
    """Append ``<tag attrs>text</tag>`` to ``parent`` and return it."""
    el = ET.SubElement(parent, tag, {k: str(v) for k, v in attrs.items()})
    if isinstance(text, bool):
        el.text = "true" if text else "false"
    elif isinstance(text, (int, float)):
        el.text = fmt(text)
    elif text is not None:
        el.text = text
    return el


def write_xml(root: ET.Element, path: Path) -> None:
    """Pretty-print ``root`` to ``path`` atomically (temporary file, then rename)."""
    path = Path(path)
    ET.indent(root, space="  ")

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            ET.ElementTree(root).write(fh, encoding="utf-8", xml_declaration=True)
            fh.write(b"\n")
    try:
        write_atomic(path, write)
    except OSError as exc:
        raise WorldError(f"{path}: cannot write ({exc.strerror})") from None
