"""The house rules, read from the code's own imports (``ast``, every import, also inside functions).

* ``sim`` (motion data, MuJoCo model, replay, rendering) never imports ``sidql``;
* the project's modules import each other without a cycle;
* imports sit at module top, except deliberately lazy heavy optional dependencies, each with a
  comment on its line saying why;
* importing the packages has no side effects and stays light.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("sim", "sidql")

#: What may be imported inside a function: heavy dependencies optional for most uses, and the
#: project's own modules that carry torch (so that the CLI and ``import sidql`` stay torch-free).
LAZY_ALLOWED = {"torch", "ray", "matplotlib", "imageio"}
LAZY_ALLOWED_MODULES = {"sidql.learning.dqn", "sidql.learning.policy"}


def project_modules() -> dict[str, Path]:
    """Dotted name -> file for every module of the project's packages (``__init__`` as the
    package name)."""
    out = {}
    for top in PACKAGES:
        for path in sorted((REPO / top).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = project_modules()


def imported_names(node: ast.Import | ast.ImportFrom, module: str) -> list[str]:
    """Dotted names an import statement refers to (``from a import b`` -> ``a.b`` and ``a``)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    base = node.module or ""
    if node.level:
        is_pkg = MODULES[module].name == "__init__.py"
        anchor = module.split(".")[: len(module.split(".")) - node.level + (1 if is_pkg else 0)]
        base = ".".join(anchor + ([base] if base else []))
    return [base] + [f"{base}.{a.name}" for a in node.names]


def resolve(name: str) -> str | None:
    """The project module a dotted name lives in (longest known prefix), or None."""
    while name:
        if name in MODULES:
            return name
        name = name.rpartition(".")[0]
    return None


def import_graph() -> dict[str, set[str]]:
    """Module -> project modules it imports (package ``__init__`` re-exports left out)."""
    graph = {}
    for mod, path in MODULES.items():
        if path.name == "__init__.py":
            continue
        targets = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for name in imported_names(node, mod):
                    t = resolve(name)
                    if t and t != mod and MODULES[t].name != "__init__.py":
                        targets.add(t)
        graph[mod] = targets
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), plus self-loops."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_graph_is_read_from_every_module():
    graph = import_graph()
    assert "sidql.keyframes.methods" in graph and "sim.replay.checks" in graph
    assert {"sidql.keyframes.reconstructions", "sim.motion.clip"} <= graph[
        "sidql.keyframes.methods"
    ]
    assert (
        "sim.model.quaternion" in graph["sidql.keyframes.pitch"]
    )  # "from sim.model import quaternion"


def test_sim_never_imports_sidql():
    up = sorted(
        f"{a} -> {b}"
        for a, bs in import_graph().items()
        for b in bs
        if a.startswith("sim.") and b.startswith("sidql.")
    )
    assert not up, "sim must not import sidql: " + ", ".join(up)


def test_no_import_cycles():
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_cycle_finder_finds_a_planted_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def function_level_imports():
    """(module, line, statement, source line) of every import inside a function."""
    for mod, path in MODULES.items():
        source = path.read_text()
        lines = source.splitlines()
        for fn in ast.walk(ast.parse(source, str(path))):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for node in ast.walk(fn):
                    if isinstance(node, (ast.Import, ast.ImportFrom)):
                        yield mod, node, lines[node.lineno - 1]


def test_imports_inside_functions_are_only_commented_lazy_heavy_dependencies():
    bad = []
    for mod, node, line in function_level_imports():
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module]
        roots = {(n or "").split(".")[0] for n in names}
        relative = isinstance(node, ast.ImportFrom) and node.level > 0
        lazy_ok = roots <= LAZY_ALLOWED or set(names) <= LAZY_ALLOWED_MODULES
        if relative or not lazy_ok:
            bad.append(f"{mod}:{node.lineno}: {ast.unparse(node)} (move it to the module top)")
        elif "#" not in line:
            bad.append(f"{mod}:{node.lineno}: {ast.unparse(node)} (say why it is lazy)")
    assert not bad, "\n".join(bad)


def run_python(code: str) -> str:
    env = {"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


@pytest.mark.slow
def test_importing_the_packages_has_no_side_effects_and_stays_light():
    code = (
        "import os, sys\n"
        "import sim, sidql\n"
        "assert 'MUJOCO_GL' not in os.environ, 'import set MUJOCO_GL'\n"
        "import sidql.keyframes.methods, sidql.keyframes.reconstructions\n"
        "heavy = [m for m in ('torch', 'mujoco', 'gymnasium', 'matplotlib') if m in sys.modules]\n"
        "assert not heavy, heavy\n"
        "for pkg in (sim, sidql):\n"
        "    for name in pkg.__all__:\n"
        "        getattr(pkg, name)\n"
        "print('torch' in sys.modules)\n"
    )
    assert run_python(code) == "False"
