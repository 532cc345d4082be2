"""The command-line front ends: help, the dataset_tools commands end to end, and user errors."""

import sys

import cv2
import pytest
from helpers import run, script


@pytest.mark.parametrize(
    "command, subcommands",
    [
        ("hqmask", ["build", "clean", "export-onnx"]),
        ("gsseg", ["train", "render", "segment", "edit", "demo"]),
        ("gseval", ["report", "compare", "paper-tables"]),
    ],
)
def test_console_scripts_list_their_subcommands(command, subcommands):
    result = run(script(command), "--help")
    assert result.returncode == 0
    for sub in subcommands:
        assert sub in result.stdout


@pytest.mark.slow
def test_synth_corrupt_inspect(tmp_path):
    py = [sys.executable, "-m", "dataset_tools"]
    scene = tmp_path / "scene"
    r = run(
        *py,
        "synth",
        "--out",
        str(scene),
        "--seed",
        "2",
        "--views",
        "5",
        "--res",
        "64",
        "--objects",
        "3",
        "--path",
        "forward",
    )
    assert r.returncode == 0, r.stderr
    r = run(
        *py, "corrupt", "--scene", str(scene), "--out-masks", "noisy", "--severity", "high", "--coarse", "--seed", "1"
    )
    assert r.returncode == 0, r.stderr
    assert len(list((scene / "noisy").glob("*.png"))) == 5
    r = run(*py, "inspect", str(scene), "--masks", "noisy")
    assert r.returncode == 0, r.stderr
    assert "5 (4 train, 1 test)" in r.stdout and "masks        noisy: 5 of 5 views" in r.stdout
    sheet = cv2.imread(str(scene / "contact_sheet.png"))
    assert sheet is not None and sheet.shape[0] > 64


@pytest.mark.parametrize(
    "args, message",
    [
        (["inspect", "{tmp}/nowhere"], "scene folder not found"),
        (["synth", "--out", "{tmp}/x", "--objects", "256"], "1..255 objects"),
        (["corrupt", "--scene", "{tmp}", "--out-masks", "n"], "image folder not found"),
    ],
)
def test_user_errors_are_one_line_and_exit_2(tmp_path, args, message):
    r = run(sys.executable, "-m", "dataset_tools", *[a.format(tmp=tmp_path) for a in args])
    assert r.returncode == 2
    assert message in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_failed_work_is_one_line_and_exit_1_and_bad_input_exit_2():
    """How a command ends: work that failed on good input (training that diverged) exits 1,
    bad input 2, each with one line and no traceback."""
    from pathlib import Path

    from dataset_tools.infra.cli_support import _failure
    from dataset_tools.infra.errors import InputError
    from gsseg.train.trainer import TrainingDiverged

    message, code = _failure(TrainingDiverged(12, float("nan"), Path("run/checkpoints/step_0000010.pt")), "gsseg")
    assert code == 1 and message.startswith("error: training diverged at step 12") and "\n" not in message
    assert "step_0000010.pt" in message
    refused = "x.png: not an image; pass a PNG."
    assert _failure(InputError(refused), "gsseg") == (f"error: {refused}", 2)


def test_a_note_on_the_command_line_is_one_line(monkeypatch, capfd):
    """A library's ``UserWarning`` reaches the command line as one ``warning: ...`` line, not
    Python's file, line number and source; other warnings go where they went before (here,
    pytest's record), and the entry point leaves the warning machinery as it found it."""
    import warnings

    import click

    from dataset_tools.infra.cli_support import run_cli

    @click.group()
    def group():
        pass

    @group.command()
    def note():
        warnings.warn("scene/: an old scene; make it again.", stacklevel=1)
        warnings.warn("old call", DeprecationWarning, stacklevel=1)

    before = warnings.showwarning
    monkeypatch.setattr(sys, "argv", ["prog", "note"])
    with pytest.warns(DeprecationWarning, match="old call") as record:
        run_cli(group, "prog")()
    assert capfd.readouterr().err == "warning: scene/: an old scene; make it again.\n"
    assert [w.category for w in record] == [DeprecationWarning]
    assert warnings.showwarning is before
