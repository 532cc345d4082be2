"""Library errors name options as their caller calls them: Python keywords from the library,
flags from the command lines; no library module writes a flag into an error itself."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import click
import pytest

from dataset_tools.infra.cli_support import WordedError, flag_spelling, word_errors_by_flags
from dataset_tools.infra.errors import InputError, OptionError, OutputExists
from dataset_tools.synth import SynthConfig
from gsseg.segment.label_options import LabelOptions
from gsseg.train.config import TrainConfig

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ("dataset_tools", "hqmask", "gsseg", "eval", "pipeline")
FLAG = re.compile(r"(?<![\w-])--[a-z]")
COMMAND = re.compile(r"`[^`]*`")  # a command to run, in backticks, may name its flags


@click.command()
@click.option("--max-gaussians", type=int)
@click.option("--fill-interiors", "fill", is_flag=True)
@click.option("--wall/--no-wall", default=True)
@click.option("--masks", default="object_mask")
@click.option("--color", type=(int, int, int))
@click.option("--force", is_flag=True)
def _command(**options):
    raise OptionError("{max_gaussians}: give 1 or more.", max_gaussians=options["max_gaussians"])


def test_an_option_error_names_python_keywords():
    with pytest.raises(OptionError) as e:
        TrainConfig(max_gaussians=0)
    assert str(e.value) == "max_gaussians=0: give 1 or more."
    assert e.value.options == ("max_gaussians",) and e.value.values == {"max_gaussians": 0}
    with pytest.raises(OptionError, match=r"^smooth and fill relabel .*; use mode='multi'\.$"):
        LabelOptions(mode="binary", smooth=4)
    with pytest.raises(OptionError, match=r"^path='spiral': use orbit or forward\.$"):
        SynthConfig(path="spiral").validate()


def test_the_file_at_fault_comes_first_and_is_data(tmp_path):
    e = OutputExists(tmp_path / "out", " or choose another {name}")
    assert e.file == tmp_path / "out"
    assert str(e) == f"{tmp_path / 'out'}: already exists; pass overwrite=True to replace it or choose another name."
    assert isinstance(e, InputError)


def test_values_must_belong_to_options_the_message_names():
    with pytest.raises(ValueError, match="iters"):
        OptionError("{max_gaussians}: give 1 or more.", iters=3)


def test_a_command_words_options_by_its_flags():
    spell = flag_spelling(_command)
    message = OptionError(
        "{max_gaussians} {fill} {wall} {masks} {color} {overwrite} {knn_reg}",
        max_gaussians=0,
        fill=True,
        wall=False,
        masks=None,
        color=(1, 2, 300),
        overwrite=True,
    ).worded(spell)
    assert message == "--max-gaussians 0 --fill-interiors --no-wall --masks none --color 1 2 300 --force --knn-reg"


def test_a_command_line_raises_the_worded_error():
    command = click.command()(click.option("--max-gaussians", type=int)(_command.callback))
    word_errors_by_flags(command)
    with pytest.raises(WordedError) as e:
        command.main(["--max-gaussians", "0"], standalone_mode=False)
    assert e.value.exit_code == 2 and e.value.format_message() == "--max-gaussians 0: give 1 or more."


def _text(node: ast.AST) -> str:
    """The literal text of a message expression, ``{}`` where a value is filled in."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(_text(part) for part in node.values)
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        return _text(node.left) + _text(node.right)
    return "{}"


def _error_texts(tree: ast.AST):
    """(line, message without its commands in backticks) of every ``raise E("...")`` of a module."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) and node.exc.args:
            yield node.lineno, COMMAND.sub("`...`", _text(node.exc.args[0]))


def test_no_library_error_names_a_flag():
    found = [
        f"{path.relative_to(ROOT)}:{line}: {text!r}"
        for package in LIBRARY
        for path in (ROOT / package).rglob("*.py")
        if path.name not in ("cli.py", "__main__.py", "cli_support.py")
        for line, text in _error_texts(ast.parse(path.read_text()))
        if FLAG.search(text)
    ]
    assert not found, "\n".join(found)


def test_the_flag_finder_sees_a_flag_and_skips_commands():
    source = 'raise E(f"{x}: pass " f"--force.")\nraise E("run `gsseg train " "--resume` again")\nraise E("a-b --c")'
    texts = dict(_error_texts(ast.parse(source)))
    assert [bool(FLAG.search(texts[line])) for line in (1, 2, 3)] == [True, False, True]


def test_an_option_error_survives_pickling_with_its_data(tmp_path):
    """A Ray task's error reaches the caller pickled."""
    import pickle

    for error in (
        OutputExists(tmp_path, " or choose another {name}", option="force"),
        OptionError("{res}: no.", res=8),
    ):
        again = pickle.loads(pickle.dumps(error))
        assert type(again) is type(error) and str(again) == str(error)
        assert (again.file, again.values, again.options) == (error.file, error.values, error.options)
        assert again.worded(flag_spelling(_command)) == error.worded(flag_spelling(_command))
