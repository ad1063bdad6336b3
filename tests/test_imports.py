"""The package's imports form no cycle (``hierloco/`` and ``recipes/``; imports inside functions count too: a cycle
hidden in a function is still a cycle), and the light modules stay light: the pipeline's records and the registry
import no simulator, network or tracker library."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def module_imports(path: Path, known: set[str]) -> set[str]:
    """The package modules ``path`` imports anywhere (module level or inside functions), resolved to known
    modules."""
    tree = ast.parse(path.read_text())
    found = set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
        for name in names:
            while name and name not in known:
                name = name.rpartition(".")[0]
            if name:
                found.add(name)
    return found


def graph() -> dict[str, set[str]]:
    paths = [p for folder in ("hierloco", "recipes") for p in (ROOT / folder).rglob("*.py")]
    known = {module_name(p) for p in paths}
    edges = {module_name(p): module_imports(p, known) for p in paths}
    for name, targets in edges.items():  # importing a.b.c imports a and a.b first
        targets.discard(name)
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    counter = [0]

    def visit(node):
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for target in edges.get(node, ()):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(10_000)
    for node in edges:
        if node not in index:
            visit(node)
    return found


def test_the_checker_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_in_the_package_or_the_recipes():
    edges = graph()
    package_edges = {name: {t for t in targets if not (name.startswith(t + ".") or t == name.rpartition(".")[0])}
                     for name, targets in edges.items()}  # a package importing its own submodules is not a cycle
    assert cycles(package_edges) == []


def test_light_modules_import_no_simulator_or_tracker():
    code = ("import sys; import hierloco.registry, hierloco.pipeline.records, hierloco.pipeline.errors; "
            "heavy = [m for m in ('torch', 'mujoco', 'ray', 'wandb', 'matplotlib', 'torchrl') if m in sys.modules]; "
            "print(','.join(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == ""
