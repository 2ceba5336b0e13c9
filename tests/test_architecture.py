"""The package's shape (issue 19): engine/ has no import cycles, counting the imports inside functions that
would otherwise hide one (not those under ``if TYPE_CHECKING:``, which never run)."""

from __future__ import annotations

import ast
from pathlib import Path

ENGINE = Path(__file__).parents[1] / "engine"


def _module(path: Path) -> str:
    parts = path.relative_to(ENGINE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _runtime_nodes(tree: ast.AST):
    """Every node of ``tree`` but those under ``if TYPE_CHECKING:``."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            continue
        yield node
        yield from _runtime_nodes(node)


def import_graph() -> dict[str, set[str]]:
    """Module -> the engine modules it imports anywhere in its body (relative or absolute)."""
    modules = {_module(p): p for p in ENGINE.rglob("*.py")}
    graph = {name: set() for name in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in _runtime_nodes(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
            elif isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                continue
            graph[name] |= {t for t in targets if t in modules and t != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected set of more than one module (Tarjan), as sorted lists."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                on.discard(w)
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                found.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_graph_sees_imports_inside_functions():
    graph = import_graph()
    assert "engine.atomic" in graph["engine.io"] and "engine.errors" in graph["engine.atomic"]
    assert "engine.features" in graph["engine.acceptance"], "an import inside a function counts"
    assert "engine.packing" not in graph["engine.plugins"], "an import for type checking does not"
    assert cycles({"a": {"b"}, "b": {"a"}, "c": set()}) == [["a", "b"]]


def test_engine_has_no_import_cycles():
    assert cycles(import_graph()) == []


def test_lint_needs_no_geometry_library():
    """Checking rule files (fuzzymesh lint, the knowledge loading) imports none of the geometry kernels."""
    import subprocess
    import sys

    heavy = ("igl", "trimesh", "gmsh", "pymeshlab", "manifold3d", "meshio")
    probe = f"import sys, engine.knowledge; print([m for m in {heavy!r} if m in sys.modules])"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=ENGINE.parent
    ).stdout.strip()
    assert out == "[]"


def test_every_named_kind_is_one_registry_checked_against_its_contract():
    """Packers, meshers, shapes, validation cases and output writers: one Registry each (engine/registry.py), each
    entry taking what its Protocol of engine/plugins.py passes; a writer for every output format of a job."""
    from engine import plugins
    from engine.io import WRITERS
    from engine.job import OUTPUT_FORMATS
    from engine.meshing import MESHERS
    from engine.packing import PACKERS
    from engine.registry import Registry
    from engine.shapes import SHAPES
    from engine.validation import CASES

    kinds = {
        PACKERS: plugins.Packer,
        MESHERS: plugins.Mesher,
        SHAPES: plugins.ShapeBuilder,
        CASES: plugins.ValidationCase,
        WRITERS: plugins.Writer,
    }
    for registry, contract in kinds.items():
        assert isinstance(registry, Registry) and registry.contract is contract
        assert len(registry) > 0
        for name in registry.names():
            assert callable(registry.get(name)), f"{registry.noun} '{name}'"
    assert list(WRITERS) and set(WRITERS) == set(OUTPUT_FORMATS)
    assert all(SHAPES.details(name)["parameters"] for name in SHAPES)


def test_a_registry_names_an_unknown_entry_and_refuses_one_off_its_contract():
    import pytest

    from engine.errors import JobError
    from engine.plugins import Writer
    from engine.registry import Registry

    writers = Registry(None, [], Writer, noun="writer")
    writers.register("ok")(lambda path, model: None)
    writers.register("bad")(lambda path: None)
    assert writers.get("ok") and list(writers) == ["ok", "bad"] and "ok" in writers
    with pytest.raises(JobError, match="no writer named 'x'"):
        writers.get("x")
    with pytest.raises(JobError, match="does not take what the pipeline passes"):
        writers.get("bad")
