"""The house rules, read from the code's own imports (``ast``, every import, also inside functions).

* ``sim`` (motion data, MuJoCo model, replay, rendering) never imports ``sidql``;
* the project's modules import each other without a cycle, and so do its rooms (the packages
  ``sim.acclaim``, ``sim.model``, ``sim.motion``, ``sim.physics``, ``sim.replay``, ...,
  ``sidql.keyframes``, ...: a room's modules may import a lower room's, never the other way);
* modules stay under :data:`MAX_MODULE_LINES` lines and functions under
  :data:`MAX_FUNCTION_LINES` (one concept per module, one step per function);
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

#: What may be imported inside a function: heavy dependencies optional for most uses, numba where
#: ``sim.jit`` imports it on purpose late (without SciPy; its loader patched once), and the
#: project's own modules that carry torch (so that the CLI and ``import sidql`` stay torch-free).
LAZY_ALLOWED = {"torch", "ray", "matplotlib", "imageio", "numba"}
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


def room(module: str) -> str:
    """The room a module lives in: its package under ``sim`` or ``sidql`` (``sim.physics`` for
    ``sim.physics.contacts``); a module directly under the top (``sim.errors``) is a room of its
    own."""
    return ".".join(module.split(".")[:2])


def room_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """Room -> the other rooms its modules import (from a module graph)."""
    out: dict[str, set[str]] = {}
    for a, bs in graph.items():
        out.setdefault(room(a), set()).update(room(b) for b in bs if room(b) != room(a))
    return out


def test_no_import_cycles_between_rooms():
    graph = import_graph()
    found = cycles(room_graph(graph))
    arrows = [
        f"{a} -> {b}"
        for c in found
        for a, bs in sorted(graph.items())
        for b in sorted(bs)
        if room(a) in c and room(b) in c and room(a) != room(b)
    ]
    assert not found, (
        "cycles between rooms: "
        + "; ".join(" <-> ".join(c) for c in found)
        + ("\n" + "\n".join(arrows))
    )


def test_room_graph_sees_a_cycle_the_module_graph_does_not():
    modules = {"p.a.x": {"p.b.y"}, "p.b.y": set(), "p.b.z": {"p.a.w"}, "p.a.w": set()}
    assert cycles(modules) == []
    assert room_graph(modules) == {"p.a": {"p.b"}, "p.b": {"p.a"}}
    assert cycles(room_graph(modules)) == [["p.a", "p.b"]]
    assert {"sim.physics", "sim.replay", "sim.motion", "sidql.keyframes"} <= set(
        room_graph(import_graph())
    )


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


#: Longest module [lines] and function [lines of its ``def`` node, decorators excluded].
MAX_MODULE_LINES, MAX_FUNCTION_LINES = 500, 80


def oversized(root: Path = REPO) -> dict[str, int]:
    """``path`` or ``path:function`` -> lines, for every module of ``sim`` and ``sidql`` over
    :data:`MAX_MODULE_LINES` and every function (or method) over :data:`MAX_FUNCTION_LINES`."""
    out = {}
    for top in PACKAGES:
        for path in sorted((root / top).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            source = path.read_text()
            if len(source.splitlines()) > MAX_MODULE_LINES:
                out[rel] = len(source.splitlines())
            for node in ast.walk(ast.parse(source, rel)):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    n = node.end_lineno - node.lineno + 1
                    if n > MAX_FUNCTION_LINES:
                        out[f"{rel}:{node.name}"] = n
    return out


def test_modules_and_functions_stay_small():
    found = oversized()
    assert not found, "over the limits (split them): " + ", ".join(
        f"{k} ({n} lines)" for k, n in sorted(found.items())
    )


def test_size_check_counts_module_and_function_lines(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    (tmp_path / "sim").mkdir()
    (tmp_path / "sidql").mkdir()
    (tmp_path / "sim" / "big.py").write_text(f"def long():\n{body}\n\n\ndef short():\n    pass\n")
    (tmp_path / "sidql" / "long.py").write_text("\n" * (MAX_MODULE_LINES + 1))
    assert oversized(tmp_path) == {
        "sim/big.py:long": MAX_FUNCTION_LINES + 1,
        "sidql/long.py": MAX_MODULE_LINES + 1,
    }


def test_every_room_is_a_package():
    """A folder of modules without ``__init__.py`` imports as a namespace package here but is
    left out of the wheel and of the API reference."""
    missing = sorted(
        str(d.relative_to(REPO))
        for top in PACKAGES
        for d in [REPO / top, *(REPO / top).rglob("*")]
        if d.is_dir() and d.name != "__pycache__" and any(d.glob("*.py"))
        and not (d / "__init__.py").is_file()
    )  # fmt: skip
    assert not missing, "folders of modules without __init__.py: " + ", ".join(missing)
