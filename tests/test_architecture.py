"""The layers of the code base, checked on the source: no import runs up, no circle.

    dataset_tools                      scene folders, synthetic scenes, SfM   (layer 0)
    hqmask, gsseg                      the two stages, side by side            (layer 1)
    eval                               metrics and reports                     (layer 2)
    pipeline                           whole runs: demo, experiments, tables   (layer 3)
    */cli.py, */__main__.py, benchmarks  entry points                         (top)

A module may import its own package and the layers below; hqmask and gsseg never import
each other. Every import counts, also those inside functions and under TYPE_CHECKING, and
importing ``a.b.c`` from outside ``a.b`` also runs ``a/b/__init__.py``, so it counts as an
import of ``a.b`` too (a package whose ``__init__`` imports back into its importer is a
circle, however far the names lie apart).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAYERS = {"dataset_tools": 0, "hqmask": 1, "gsseg": 1, "eval": 2, "pipeline": 3, "benchmarks": 4}
TOP = 4
ENTRY_POINTS = ("cli", "__main__")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for package in LAYERS for p in (ROOT / package).rglob("*.py")}


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The project modules ``name`` imports: the most specific known module of every target."""
    tree = ast.parse(path.read_text(), str(path))
    is_package = path.name == "__init__.py"
    targets = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = name.split(".")
                anchor = anchor[: len(anchor) - node.level + (1 if is_package else 0)]
                base = ".".join(anchor + ([base] if base else []))
            targets |= {f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names}
    out = set()
    for target in targets:
        while target and target not in known:
            target = target.rpartition(".")[0]
        # the target and the packages it lies in that do not also hold the importer
        while target and not (name + ".").startswith(target + "."):
            if target in known and target != name:
                out.add(target)
            target = target.rpartition(".")[0]
    return out


def layer(name: str) -> int:
    parts = name.split(".")
    return TOP if parts[-1] in ENTRY_POINTS else LAYERS[parts[0]]


def graph() -> dict[str, set[str]]:
    found = modules()
    return {name: imports(name, path, set(found)) for name, path in found.items()}


def test_no_import_runs_up_the_layers():
    wrong = []
    for name, targets in graph().items():
        for target in targets:
            same_package = target.split(".")[0] == name.split(".")[0]
            if not same_package and layer(target) >= layer(name):
                wrong.append(f"{name} (layer {layer(name)}) imports {target} (layer {layer(target)})")
    assert not wrong, "\n".join(sorted(wrong))


def test_no_import_circle():
    edges = graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    assert not circles, "\n".join(" <-> ".join(c) for c in circles)


def test_the_checker_sees_function_level_and_relative_imports(tmp_path):
    """The walker itself: an import inside a function, a relative import and the package an
    outside import runs are all edges; a sibling's own package is not."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from pkg.b import g\n")
    (pkg / "b.py").write_text("from . import a\n")
    (tmp_path / "c.py").write_text("import pkg.a\n")
    known = {"pkg", "pkg.a", "pkg.b", "c"}
    global ROOT
    saved, ROOT = ROOT, tmp_path
    try:
        assert imports("pkg.a", pkg / "a.py", known) == {"pkg.b"}
        assert imports("pkg.b", pkg / "b.py", known) == {"pkg.a"}
        assert imports("c", tmp_path / "c.py", known) == {"pkg.a", "pkg"}
    finally:
        ROOT = saved
