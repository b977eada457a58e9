"""Check a world (or model) for the problems that stop Gazebo or dartpy from loading it.

``check_world(path)`` returns one-line problems (empty list = fine):

* ``ign sdf -k`` (libsdformat's checker) when ``ign`` is installed: its ``Error`` lines. It is
  run with ``SDF_PATH`` set to the model search folders of :mod:`worlds.sdf_read`, plus a
  stand-in for Gazebo's stock ``ground_plane`` model when the world includes it;
* every ``<mesh><uri>`` of the file and of the models it includes resolves to a file inside
  the world's folder or the model path (:func:`worlds.sdf_read.allowed_roots`);
* every SDF file's version is between 1.4 and 1.6 (dartpy's SdfParser refuses 1.7+).
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

from worlds.sdf_read import (GROUND_MODELS, _model_not_found, allowed_roots, find_model,
                             model_file, model_search_dirs, pick_file, resolve_uri)
from worlds.sdf_xml import SDF_VERSION, WorldError, XmlDoc, parse_xml, sub, text_of, write_xml

MIN_VERSION = (1, 4)
MAX_VERSION = tuple(int(p) for p in SDF_VERSION.split("."))
IGN_TIMEOUT_S = 120.0
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def check_world(path: str | Path, *, use_ign: bool = True) -> list[str]:
    """Problems of a world/model file or folder (see the module docstring)."""
    try:
        source = pick_file(Path(path))
        roots = allowed_roots(source)
        docs, problems = _collect(source, roots)
    except WorldError as exc:
        return [str(exc)]
    for doc in docs:
        problems += _version_problems(doc)
        for mesh in doc.root.iter("mesh"):
            uri_el = mesh.find("uri")
            if not text_of(uri_el):
                problems.append(doc.error(mesh, "<mesh> without a <uri>").args[0])
                continue
            try:
                resolve_uri(text_of(uri_el), doc, uri_el, [source.parent], roots)
            except WorldError as exc:
                problems.append(str(exc))
    if use_ign and shutil.which("ign"):
        uses_ground = any(_include_target(inc) in GROUND_MODELS for d in docs
                          for inc in d.root.iter("include"))
        problems += ign_check(source, ground_stub=uses_ground)
    return problems


def _include_target(inc: ET.Element) -> str | None:
    uri = text_of(inc.find("uri"))
    return uri[len("model://"):].rstrip("/") if uri.startswith("model://") else None


def _collect(source: Path, roots: tuple[Path, ...]) -> tuple[list[XmlDoc], list[str]]:
    """The file and every model file it includes (recursively); unresolved includes."""
    docs, problems, seen = [], [], set()
    todo = [source]
    while todo:
        path = todo.pop(0).resolve()
        if path in seen:
            continue
        seen.add(path)
        doc = parse_xml(path) if path == source.resolve() else _parse_or_none(path, problems)
        if doc is None:
            continue
        docs.append(doc)
        for inc in doc.root.iter("include"):
            name = _include_target(inc)
            if name is None or name in GROUND_MODELS:
                continue
            model_dir = find_model(name, [path.parent, source.parent], roots)
            if model_dir is None:
                problems.append(doc.error(inc, _model_not_found(name, f"model://{name}",
                                                                [path.parent, source.parent])).args[0])
                continue
            try:
                todo.append(model_file(model_dir))
            except WorldError as exc:
                problems.append(str(exc))
    return docs, problems


def _parse_or_none(path: Path, problems: list[str]) -> XmlDoc | None:
    try:
        return parse_xml(path)
    except WorldError as exc:
        problems.append(str(exc))
        return None


def _version_problems(doc: XmlDoc) -> list[str]:
    text = doc.root.get("version")
    if doc.root.tag != "sdf":
        return [doc.error(doc.root, f"expected <sdf> as the root element, found <{doc.root.tag}>").args[0]]
    if text is None:
        return [doc.error(doc.root, "<sdf> has no version attribute (expected 1.4 .. 1.6)").args[0]]
    try:
        version = tuple(int(p) for p in text.split("."))
    except ValueError:
        return [doc.error(doc.root, f"SDF version '{text}' is not a version number").args[0]]
    if not MIN_VERSION <= version <= MAX_VERSION:
        return [doc.error(doc.root, f"SDF version {text}: expected 1.4 .. {SDF_VERSION} "
                          "(dartpy's SdfParser reads no other)").args[0]]
    return []


def _write_ground_stub(folder: Path) -> None:
    model_dir = folder / "ground_plane"
    model_dir.mkdir()
    config = ET.Element("model")
    sub(config, "name", "ground_plane")
    sub(config, "sdf", "model.sdf", version=SDF_VERSION)
    write_xml(config, model_dir / "model.config")
    root = ET.Element("sdf", version=SDF_VERSION)
    model = sub(root, "model", name="ground_plane")
    sub(model, "static", True)
    collision = sub(sub(model, "link", name="link"), "collision", name="collision")
    plane = sub(sub(collision, "geometry"), "plane")
    sub(plane, "normal", "0 0 1")
    sub(plane, "size", "100 100")
    write_xml(root, model_dir / "model.sdf")


def ign_check(source: Path, *, ground_stub: bool = False) -> list[str]:
    """Run ``ign sdf -k source``; its error lines as problems (empty when Valid)."""
    with tempfile.TemporaryDirectory(prefix="nxpcup-sdf-") as tmp:
        dirs = [str(d) for d in model_search_dirs([source.parent])]
        if ground_stub:
            _write_ground_stub(Path(tmp))
            dirs.append(tmp)
        env = dict(os.environ, SDF_PATH=os.pathsep.join(dirs))
        try:
            proc = subprocess.run(["ign", "sdf", "-k", str(source)], capture_output=True, text=True,
                                  env=env, timeout=IGN_TIMEOUT_S, check=False)
        except (OSError, subprocess.TimeoutExpired) as exc:
            return [f"{source}: could not run 'ign sdf -k' ({exc})"]
    if proc.returncode == 0:
        return []
    lines = [_ANSI.sub("", ln).strip() for ln in (proc.stdout + "\n" + proc.stderr).splitlines()]
    errors = [ln for ln in lines if ln.startswith("Error Code")]
    if not errors:
        errors = [ln for ln in lines if ln and "libignition-tools-backward" not in ln][:3] or \
                 [f"exit code {proc.returncode}"]
    return [f"{source}: ign sdf -k: {ln}" for ln in errors]
