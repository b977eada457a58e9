"""The import direction follows the data flow: nothing below imports anything above.

Packages, bottom to top: pieces, vehicle, worlds, trackgen, simrunner. Inside simrunner:
errors, track, car, sensors, telemetry, reports, run, workflows, gym, cli (the package's own ``__init__`` is its
public facade and may name anything). Every import counts, also those inside functions.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ["pieces", "vehicle", "worlds", "trackgen", "simrunner"]
SIMRUNNER = ["errors", "track", "car", "sensors", "telemetry", "reports", "run", "workflows", "gym", "cli"]


def rank(module: str) -> tuple[int, int] | None:
    parts = module.split(".")
    if parts[0] not in PACKAGES:
        return None
    top = PACKAGES.index(parts[0])
    if parts[0] != "simrunner" or len(parts) == 1:
        return (top, -1)
    sub = parts[1]
    return (top, SIMRUNNER.index(sub) if sub in SIMRUNNER else -1)


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imports(path: Path, name: str) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.append(mod)
            out += [f"{mod}.{a.name}" for a in node.names]  # `from simrunner import run`
    return out


FILES = sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def violations(name: str, targets: list[str]) -> list[str]:
    """The imports of module ``name`` that sit above it."""
    mine = rank(name)
    bad = []
    for target in targets:
        r = rank(target)
        if r is None or target.split(".")[:2] == name.split(".")[:2]:
            continue
        if r[0] > mine[0] or (r[0] == mine[0] == PACKAGES.index("simrunner") and r[1] > mine[1]):
            bad.append(target)
    return sorted(set(bad))


def test_the_check_sees_upward_imports():
    assert violations("simrunner.car.physics", ["simrunner.run.clock", "simrunner.errors"]) == [
        "simrunner.run.clock"]
    assert violations("worlds.sdf_write", ["trackgen.build", "pieces.pose"]) == ["trackgen.build"]
    assert violations("simrunner.cli.gap", ["simrunner.workflows.gap", "trackgen"]) == []


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_nothing_below_imports_anything_above(path):
    name = module_name(path)
    if name == "simrunner":
        return  # the facade
    bad = violations(name, imports(path, name))
    assert not bad, f"{name} imports {bad}, which sit above it"


# -- import circles -----------------------------------------------------------------------------
# Circles that are still there (issue 48 removes them: the telemetry room, the gap chain); no new one may appear, and a removed one must leave this list.
KNOWN_CIRCLES: set[frozenset[str]] = set()  # none left: a new one fails, as one that comes back


def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (any import: top level, in functions, under
    TYPE_CHECKING); an import of a package's name counts for its ``__init__``."""
    names = {module_name(p): p for p in FILES}
    graph: dict[str, set[str]] = {}
    for name, path in names.items():
        out = set()
        for target in imports(path, name):
            while target and target not in names:
                target = target.rsplit(".", 1)[0] if "." in target else ""
            if target and target != name and not name.startswith(target + "."):
                out.add(target)  # (a module importing its own package's facade is not a circle)
        graph[name] = out
    return graph


def circles(graph: dict[str, set[str]]) -> set[frozenset[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: set[frozenset[str]] = set()

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.add(frozenset(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_circle_finder_finds_circles():
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == {frozenset("abc")}
    assert circles({"a": {"b"}, "b": set()}) == set()


def test_no_new_import_circles():
    found = circles(import_graph())
    assert not found - KNOWN_CIRCLES, f"new import circles: {[sorted(c) for c in found - KNOWN_CIRCLES]}"
    assert not KNOWN_CIRCLES - found, f"gone, remove from KNOWN_CIRCLES: {[sorted(c) for c in KNOWN_CIRCLES - found]}"


def design_file_list() -> dict[str, str]:
    """docs/DESIGN.md's file list: each bullet ``- `folder/`: ...`` (or ``- `file.py`: ...``)
    by the folder or file it starts with."""
    import re

    text = (ROOT / "docs" / "DESIGN.md").read_text(encoding="utf-8")
    section = text[text.index("\n- `pieces/`"):text.index("\n## Conventions")]
    bullets = {}
    for block in re.split(r"\n- (?=`)", section):
        m = re.match(r"`([\w/.]+)`", block.strip("- \n"))
        if m:
            bullets[m.group(1).rstrip("/")] = block
    return bullets


def test_design_file_list_names_every_module():
    import re

    bullets = design_file_list()
    missing = []
    for path in FILES:
        if path.name == "__init__.py":
            continue
        rel = path.relative_to(ROOT).as_posix()
        if rel in bullets:
            continue
        owners = [b for b in bullets if rel.startswith(b + "/")]
        stem = re.escape(path.stem)
        if not owners or not re.search(rf"`{stem}(\.py)?`|`{stem}\b", bullets[max(owners, key=len)]):
            missing.append(rel)
    assert not missing, f"docs/DESIGN.md's file list does not name: {missing}"
