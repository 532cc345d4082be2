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

The run folder has one owner, ``gsseg/run/folder.py``: no other module reads or writes a
run's files.
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


RUN_FILES = ("config", "gaussians", "classifier", "environment", "metrics", "labels", "contributions", "evaluation")
RUN_FILE_NAMES = (
    "config.json",
    "classifier.pt",
    "environment.pt",
    "labels.npz",
    "contributions.npz",
    "evaluation.json",
    "edit.json",
)
OPENERS = ("open", "read_text", "read_bytes", "write_text", "write_bytes")


def _is_run_file(node: ast.AST) -> bool:
    """``folder.<file>`` or ``<x>.folder.<file>``: the path of a run file."""
    if not (isinstance(node, ast.Attribute) and node.attr in RUN_FILES):
        return False
    owner = node.value
    return (isinstance(owner, ast.Name) and owner.id == "folder") or (
        isinstance(owner, ast.Attribute) and owner.attr == "folder"
    )


def run_file_access(source: str) -> list[int]:
    """Lines of ``source`` that open a run file: a run file's path opened or passed to a call
    (``np.load(run.folder.labels)``; an error's ``file=`` only names it), or a run file's name
    joined onto a path (``run / "labels.npz"``)."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call):
            f = node.func
            opened = isinstance(f, ast.Attribute) and f.attr in OPENERS and _is_run_file(f.value)
            passed = [*node.args, *(k.value for k in node.keywords if k.arg != "file")]
            if opened or any(_is_run_file(a) for a in passed):
                lines.append(node.lineno)
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div):
            if isinstance(node.right, ast.Constant) and node.right.value in RUN_FILE_NAMES:
                lines.append(node.lineno)
    return sorted(lines)


def test_only_the_run_folder_module_opens_run_files():
    owner = ROOT / "gsseg" / "run" / "folder.py"
    found = [
        f"{path.relative_to(ROOT)}:{line}"
        for path in modules().values()
        if path != owner
        for line in run_file_access(path.read_text())
    ]
    assert not found, "run files opened outside gsseg/run/folder.py:\n" + "\n".join(found)


def test_the_run_file_checker_sees_reads_writes_and_joined_names():
    """The checker itself: each way of opening a run file is seen; naming one in a message,
    asking whether it exists or opening another folder's file is not."""
    opened = (
        "np.load(run.folder.labels)\n"
        "folder.config.read_text()\n"
        "torch.load(path=self.run.folder.classifier)\n"
        "(run / 'labels.npz').unlink()\n"
        "write_json(folder.metrics, {})\n"
    )
    assert run_file_access(opened) == [1, 2, 3, 4, 5]
    fine = (
        "raise InputError(f'{run.folder.labels} is missing')\n"
        "raise OptionError('trained with {seed}', file=folder.config, seed=0)\n"
        "run.folder.labels.is_file()\n"
        "np.load(scene / 'points.npz')\n"
        "labels.read_text()\n"
    )
    assert run_file_access(fine) == []
