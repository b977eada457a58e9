"""How ``pytest -n 2`` (``make test``) shares the tests between its workers.

A test that uses a module-scoped (or class-scoped) fixture of its own module, directly or
through another fixture of that module, or any test of a module with such a fixture on
autouse, joins that module's group: the group runs on one worker, so the fixture (a
simulated log and its gap run, a Ray cluster, a build cache) is made once. Every other test
is scheduled on its own, to whichever worker is free, so that slow tests do not queue
behind each other on one worker while the other has nothing left: pytest-xdist's default
(``--dist load``) sent test_gap.py's 330 s to one worker in one chunk, and the other idled
for the last two minutes of a 9.8-minute run. The groups go first, largest first, then the
single tests in file order (pytest-xdist's ``loadscope`` scheduler, whose unit of work this
file chooses).

Why not ``xdist_group`` marks and ``--dist loadgroup``: pytest-xdist 3.8 names a group by
rewriting ``item._nodeid``, which pytest 9 no longer reads (it keeps the id in ``item._id``),
so the marks are silently ignored. The controller does not collect tests, so the groups
are found here from the test modules' source (their ``@pytest.fixture(scope=...)``
functions and the parameters that name them).
"""
from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _fixture_scope(func: ast.FunctionDef) -> tuple[bool, str, bool]:
    """(is a fixture, its scope, autouse) from ``func``'s decorators."""
    for dec in func.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        if isinstance(target, ast.Attribute) and target.attr == "fixture":
            kw = {k.arg: k.value for k in dec.keywords} if isinstance(dec, ast.Call) else {}
            scope = kw.get("scope")
            autouse = kw.get("autouse")
            return (True, scope.value if isinstance(scope, ast.Constant) else "function",
                    isinstance(autouse, ast.Constant) and autouse.value is True)
    return False, "", False


@functools.lru_cache(maxsize=None)
def _shared_tests(module: str) -> frozenset[str] | None:
    """The test functions of ``module`` (a path from the root) that use one of its module- or
    class-scoped fixtures; None when every test does (such a fixture is autouse)."""
    try:
        tree = ast.parse((ROOT / module).read_text())
    except (OSError, SyntaxError, ValueError):
        return frozenset()
    funcs = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    params = {f.name: {a.arg for a in f.args.args + f.args.kwonlyargs} for f in funcs}
    fixtures = {f.name: _fixture_scope(f) for f in funcs if _fixture_scope(f)[0]}
    shared = {name for name, (_, scope, _) in fixtures.items() if scope in ("module", "class")}
    if any(fixtures[name][2] for name in shared):
        return None
    grew = True
    while grew:  # a fixture of any scope that uses a shared one shares it too
        more = {name for name in fixtures if name not in shared and params[name] & shared}
        shared |= more
        grew = bool(more)
    return frozenset(f.name for f in funcs if f.name.startswith("test") and params[f.name] & shared)


def group_of(nodeid: str) -> str:
    """The unit of work of the test ``nodeid``: its module if it shares a fixture, else itself."""
    module, _, rest = nodeid.partition("::")
    if not rest:
        return nodeid
    shared = _shared_tests(module)
    function = rest.split("::")[-1].split("[", 1)[0]
    return module if shared is None or function in shared else nodeid


def pytest_xdist_make_scheduler(config, log):
    """Under ``-n N`` (``--dist load``, its default); another ``--dist`` keeps its own."""
    if config.getoption("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class SharedFixtureScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return group_of(nodeid)

    return SharedFixtureScheduling(config, log)
