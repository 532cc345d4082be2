"""Each default and each choice list is written once: in the library's option dataclasses and
registries. The command lines read them, pass on only the flags given, and make the same
options as Python does from the same values."""

from __future__ import annotations

import ast
import functools
import importlib
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from dataset_tools.cli import cli as dataset_cli
from eval.cli import cli as eval_cli
from gsseg.cli import cli as gsseg_cli
from hqmask.cli import cli as hqmask_cli

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("dataset_tools", "hqmask", "gsseg", "eval", "pipeline", "benchmarks")
# Values that choose nothing: off, none, the identity, and "auto" (the library decides).
NEUTRAL = (None, True, False, 0, 1, 0.0, 1.0, "", "auto")
GROUPS = (gsseg_cli, hqmask_cli, eval_cli, dataset_cli)


def _trees() -> dict[str, ast.Module]:
    return {
        str(p.relative_to(ROOT)): ast.parse(p.read_text())
        for package in SOURCES
        for p in sorted((ROOT / package).rglob("*.py"))
    }


def _literal(node: ast.AST) -> object:
    """The value of a literal number or string (negative numbers included); raises ValueError."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return -_literal(node.operand)
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float, str)):
        return node.value
    raise ValueError


def _neutral(value: object) -> bool:
    return any(value == n and type(value) is type(n) for n in NEUTRAL)


def _dataclass_defaults(trees: dict[str, ast.Module]) -> list[tuple[str, str, object, int]]:
    """(file, class.field, value, line) of every dataclass field whose default is a literal
    that chooses something."""
    found = []
    for file, tree in trees.items():
        for cls in ast.walk(tree):
            if not isinstance(cls, ast.ClassDef) or not any("dataclass" in ast.unparse(d) for d in cls.decorator_list):
                continue
            for stmt in cls.body:
                if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and stmt.value is not None:
                    try:
                        value = _literal(stmt.value)
                    except ValueError:
                        continue
                    if not _neutral(value):
                        found.append((file, f"{cls.name}.{stmt.target.id}", value, stmt.lineno))
    return found


def _flag_name(call: ast.Call) -> str | None:
    """The parameter name of a ``click.option(...)`` call."""
    names = [a.value for a in call.args if isinstance(a, ast.Constant) and isinstance(a.value, str)]
    plain = [n for n in names if not n.startswith("-")]
    flags = [n for n in names if n.startswith("--")]
    return plain[0] if plain else flags[0][2:].split("/")[0].replace("-", "_") if flags else None


def _default_copies(tree: ast.Module) -> list[tuple[str, object, int]]:
    """(name, value, line) of every literal default of a function parameter or of a click
    option in ``tree``."""
    copies = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            args = node.args
            positional = args.posonlyargs + args.args
            pairs = list(zip(positional[len(positional) - len(args.defaults) :], args.defaults))
            pairs += [(a, d) for a, d in zip(args.kwonlyargs, args.kw_defaults) if d is not None]
            for arg, default in pairs:
                try:
                    copies.append((arg.arg, _literal(default), node.lineno))
                except ValueError:
                    pass
        elif isinstance(node, ast.Call) and ast.unparse(node.func).endswith("option"):
            for keyword in node.keywords:
                if keyword.arg == "default" and (name := _flag_name(node)):
                    try:
                        copies.append((name, _literal(keyword.value), node.lineno))
                    except ValueError:
                        pass
    return copies


def test_no_default_of_an_option_dataclass_is_written_again():
    """A literal default of a dataclass field is not written again as the default of a
    parameter or a command-line option of the same name, nor of another dataclass's field
    (passing a value explicitly, as a benchmark's setup does, is a choice, not a copy)."""
    trees = _trees()
    fields = _dataclass_defaults(trees)
    by_name: dict[str, list[tuple[str, str, object, int]]] = {}
    for entry in fields:
        by_name.setdefault(entry[1].split(".")[1], []).append(entry)
    copies = []
    for name, entries in by_name.items():
        for i, (file, field, value, line) in enumerate(entries):
            copies += [
                f"{file}:{line} {field} = {value!r}, as {other}"
                for _, other, other_value, _ in entries[:i]
                if other_value == value
            ]
    for file, tree in trees.items():
        for name, value, line in _default_copies(tree):
            copies += [
                f"{file}:{line} {name}={value!r} copies {field}"
                for _, field, field_value, _ in by_name.get(name, ())
                if field_value == value and type(field_value) is type(value)
            ]
    assert not copies, "defaults written twice:\n" + "\n".join(copies)


def _string_list(node: ast.AST) -> set[str] | None:
    """The strings of a literal tuple, list or set of two or more strings."""
    if not isinstance(node, (ast.Tuple, ast.List, ast.Set)) or len(node.elts) < 2:
        return None
    if all(isinstance(i, ast.Constant) and isinstance(i.value, str) for i in node.elts):
        return {i.value for i in node.elts}
    return None


def test_no_registry_is_typed_out_again():
    """A module-level registry (an upper-case tuple or dict of names) is the one place its
    names are listed: no literal list of the same names stands anywhere else."""
    trees = _trees()
    registries, definitions = {}, set()
    for file, tree in trees.items():
        for stmt in tree.body:
            target = stmt.targets[0] if isinstance(stmt, ast.Assign) else getattr(stmt, "target", None)
            if isinstance(target, ast.Name) and target.id.isupper() and stmt.value is not None:
                names = _string_list(stmt.value)
                if names is None and isinstance(stmt.value, ast.Dict) and stmt.value.keys:
                    keys = stmt.value.keys
                    if all(isinstance(k, ast.Constant) and isinstance(k.value, str) for k in keys):
                        names = {k.value for k in keys}
                if names:
                    registries[f"{file}:{target.id}"] = names
                    definitions.add(id(stmt.value))
    assert {"gsseg/edits.py:OPS", "hqmask/build_options.py:ASSOCIATIONS"} <= set(registries)
    typed = [
        f"{file}:{node.lineno} {sorted(names)} is {where}"
        for file, tree in trees.items()
        for node in ast.walk(tree)
        if id(node) not in definitions and (names := _string_list(node))
        for where, registered in registries.items()
        if names == registered
    ]
    assert not typed, "registries typed out again:\n" + "\n".join(typed)


def _commands():
    for group in GROUPS:
        for name, command in group.commands.items():
            yield f"{group.name} {name}", command


def _option(command: click.Command, name: str) -> click.Option | None:
    return next((p for p in command.params if isinstance(p, click.Option) and p.name == name), None)


def test_a_backend_proposer_or_edit_added_to_its_registry_is_a_choice_everywhere(monkeypatch):
    """Adding one touches its registry alone: every option that chooses among them reads it."""
    from gsseg.edits import OPS
    from gsseg.render.backends import BACKENDS
    from hqmask.proposers.registry import PROPOSERS

    monkeypatch.setitem(BACKENDS, "mine", BACKENDS["cpu"])
    monkeypatch.setitem(PROPOSERS, "mine", PROPOSERS["graph"])
    monkeypatch.setattr("gsseg.edits.OPS", (*OPS, "mine"))
    backends = [(where, _option(c, "backend")) for where, c in _commands() if _option(c, "backend")]
    assert len(backends) >= 8
    for where, option in backends:
        assert tuple(option.type.choices) == ("auto", *BACKENDS), where
    assert "mine" in _option(hqmask_cli.commands["build"], "proposer").type.choices
    assert "mine" in _option(gsseg_cli.commands["edit"], "op").type.choices


class _Captured(Exception):
    """Raised by a stand-in for a library entry point, carrying what the command passed it."""


def _capture(monkeypatch, target: str) -> None:
    """Replace the function ``target`` (``module.name``) by one of the same signature that
    raises what it was passed."""
    module, name = target.rsplit(".", 1)
    original = getattr(importlib.import_module(module), name)

    @functools.wraps(original)
    def stand_in(*args, **kwargs):
        raise _Captured(args, kwargs)

    monkeypatch.setattr(target, stand_in)


def _passed(group: click.Group, argv: list[str]) -> tuple[tuple, dict]:
    result = CliRunner().invoke(group, argv)
    assert isinstance(result.exception, _Captured), result.output
    return result.exception.args


@pytest.mark.parametrize(
    "argv, python",
    [
        ([], {}),
        (["--backend", "gsplat"], {"backend": "gsplat"}),
        (["--backend", "gsplat", "--schedule", "auto"], {"backend": "gsplat", "schedule": "auto"}),
        (["--schedule", "cpu", "--backend", "gsplat"], {"schedule": "cpu", "backend": "gsplat"}),
        (
            ["--masks", "none", "--environment", "none", "--no-environment-profile", "--iters", "7", "--seed", "3"],
            {"masks": None, "environment_degree": None, "environment_profile": False, "iters": 7, "seed": 3},
        ),
        (
            ["--gamma-obj", "0.5", "--knn-reg", "0.1", "--max-gaussians", "9"],
            {"gamma_obj": 0.5, "knn_reg": 0.1, "max_gaussians": 9},
        ),
    ],
)
def test_gsseg_train_makes_the_config_python_makes(monkeypatch, tmp_path, argv, python):
    """``schedule="auto"`` is resolved by the config itself: ``--backend gsplat`` from the
    command line and ``TrainConfig(backend="gsplat")`` both get the paper's schedule."""
    from gsseg.train.config import TrainConfig

    _capture(monkeypatch, "gsseg.train.trainer.train")
    (_, _, cfg), kwargs = _passed(gsseg_cli, ["train", str(tmp_path), "--out", str(tmp_path / "run"), *argv])
    assert cfg == TrainConfig(**python)
    assert kwargs["given"] == set(python)
    if python.get("backend") == "gsplat" and "schedule" not in argv[2:] and python.get("schedule") != "cpu":
        assert cfg.schedule == "gpu" and cfg.timing.iters == 30_000


@pytest.mark.parametrize(
    "group, argv, target, owner, python",
    [
        (gsseg_cli, ["segment", "run"], "gsseg.segment.segment_run.segment_run", "LabelOptions", {}),
        (
            gsseg_cli,
            ["segment", "run", "--method", "flashsplat", "--slack", "0.1", "--smooth", "4", "--fill-interiors"],
            "gsseg.segment.segment_run.segment_run",
            "LabelOptions",
            {"method": "flashsplat", "slack": 0.1, "smooth": 4, "fill": True},
        ),
        (hqmask_cli, ["build", "scene"], "hqmask.build.build_masks", "BuildConfig", {}),
        (
            hqmask_cli,
            ["build", "scene", "--associate", "flow", "--consensus", "0", "--min-area", "20", "--out-masks", "m"],
            "hqmask.build.build_masks",
            "BuildConfig",
            {"associate": "flow", "consensus": 0, "min_area": 20, "out_masks": "m"},
        ),
        (gsseg_cli, ["demo"], "pipeline.demo.run_demo", "DemoOptions", {}),
        (
            gsseg_cli,
            ["demo", "--scene", "photos", "--iters", "5", "--max-gaussians", "7", "--backend", "cpu"],
            "pipeline.demo.run_demo",
            "DemoOptions",
            {"scene": Path("photos"), "iters": 5, "max_gaussians": 7, "backend": "cpu"},
        ),
        (dataset_cli, ["synth", "--out", "s"], "dataset_tools.synth.generate_scene", "SynthConfig", {}),
        (
            dataset_cli,
            ["synth", "--out", "s", "--path", "forward", "--no-wall", "--res", "64"],
            "dataset_tools.synth.generate_scene",
            "SynthConfig",
            {"path": "forward", "wall": False, "res": 64},
        ),
        (dataset_cli, ["sfm", "photos", "--out", "s"], "dataset_tools.sfm.run_sfm", "SfmConfig", {}),
        (
            dataset_cli,
            ["sfm", "photos", "--out", "s", "--matcher", "retrieval", "--camera-per-folder", "--parallel-sift"],
            "dataset_tools.sfm.run_sfm",
            "SfmConfig",
            {"matcher": "retrieval", "single_camera": False, "deterministic": False},
        ),
    ],
)
def test_every_command_makes_the_options_python_makes(monkeypatch, group, argv, target, owner, python):
    from dataset_tools.sfm import SfmConfig
    from dataset_tools.synth import SynthConfig
    from gsseg.segment.label_options import LabelOptions
    from hqmask.build_options import BuildConfig
    from pipeline.demo_options import DemoOptions

    owners = {c.__name__: c for c in (LabelOptions, BuildConfig, DemoOptions, SynthConfig, SfmConfig)}
    _capture(monkeypatch, target)
    args, kwargs = _passed(group, argv)
    made = next(v for v in (*args, *kwargs.values()) if isinstance(v, owners[owner]))
    assert made == owners[owner](**python)


def test_dataset_tools_corrupt_passes_the_flags_given_alone(monkeypatch):
    """A command over a library function hands it the flags the user gave and lets the
    function's own defaults decide the rest."""
    _capture(monkeypatch, "dataset_tools.cli.corrupt_scene")
    args, kwargs = _passed(dataset_cli, ["corrupt", "--scene", "s", "--out-masks", "m", "--seed", "2"])
    assert args == (Path("s"),) and kwargs == {"overwrite": False, "out_masks": "m", "seed": 2}


def test_no_command_lost_a_flag():
    """The flags that the documentation and scripts use, per command (a command line built
    from the dataclasses keeps every one of them)."""
    expected = {
        "gsseg train": "--masks --images --iters --schedule --backend --gamma-obj --geometry-from-masks --knn-reg "
        "--environment --environment-profile --max-gaussians --seed --resume --allow-other-scene --stop-after "
        "--cache-views",
        "gsseg segment": "--scene --method --mode --gamma-p --slack --smooth --fill-interiors --masks --backend",
        "gsseg demo": "--out --scene --images --iters --max-gaussians --backend --force",
        "hqmask build": "--proposer --from-masks --model --associate --consensus --min-area --out-masks --images "
        "--dataset --force --device --threads --points-per-side --cache-embeddings --depth --engine --address",
        "python sfm": "--frames --matcher --neighbours --mapper --camera-model --single-camera --max-image-size "
        "--peak-threshold --scale-thresholds --deterministic --seed --force",
        "python synth": "--seed --views --res --objects --path --wall --ground --edit-truth --force",
    }
    commands = {where.replace("python -m dataset_tools", "python"): c for where, c in _commands()}
    commands |= {f"python {n}": c for n, c in dataset_cli.commands.items()}
    for where, flags in expected.items():
        have = {opt for p in commands[where].params for opt in getattr(p, "opts", ())}
        assert set(flags.split()) <= have, (where, set(flags.split()) - have)


def test_the_helps_show_the_dataclasses_defaults():
    from gsseg.segment.label_options import LabelOptions
    from gsseg.train.config import TrainConfig
    from hqmask.build_options import BuildConfig

    def help_of(group: click.Group, command: str) -> str:
        return CliRunner().invoke(group, [command, "--help"], terminal_width=500, max_content_width=500).output

    helps = {"train": help_of(gsseg_cli, "train"), "segment": help_of(gsseg_cli, "segment")}
    helps["build"] = help_of(hqmask_cli, "build")
    assert f"[default: {LabelOptions.gamma_p}]" in helps["segment"]
    assert f"[default: {TrainConfig.gamma_obj}]" in helps["train"]
    assert (
        f"[default: {BuildConfig.consensus};" in helps["build"]
        or f"[default: {BuildConfig.consensus}]" in helps["build"]
    )
    assert "[default: auto]" in helps["train"] and "--schedule [auto|gpu|cpu]" in helps["train"]
