"""The command lines share one convention: 2 for a usage error (argparse's message), 1 for bad
input data (one line naming what is wrong, no traceback), and a traceback for anything else."""

import argparse

import pytest

from jbevo.cli import common, demo, evaluate, localize, metrics, render, train
from jbevo.geometry import BevGrid

COMMANDS = {
    "train": train.main,
    "evaluate": evaluate.main,
    "localize": localize.main,
    "metrics": metrics.main,
    "demo": demo.main,
    "render": render.main,
}


@pytest.mark.parametrize(
    "name, argv",
    [
        ("train", ["--epochs", "0"]),
        ("train", ["--grid", "0.1", "12.5", "7.5"]),
        ("train", ["--frames", "-3"]),
        ("evaluate", ["--attitude", "sideways"]),
        ("localize", ["fly"]),
        ("localize", ["train", "--window", "zero"]),
        ("metrics", ["--gt", "a.txt"]),
        ("demo", ["--steps", "0"]),
        ("render", ["--frames", "3"]),
    ],
)
def test_usage_errors_exit_with_2(name, argv, capsys):
    with pytest.raises(SystemExit) as exit:
        COMMANDS[name](argv)
    assert exit.value.code == 2
    assert "usage:" in capsys.readouterr().err


def test_the_grid_option_takes_whole_pixels():
    parser = common.parser("p", None, [common.grid_option(BevGrid(0.1, (64, 64)))])
    grid = parser.parse_args(["--grid", "0.05", "96", "3.0"]).grid
    assert grid == BevGrid(0.05, (96, 96), near=3.0)
    assert parser.parse_args([]).grid == BevGrid(0.1, (64, 64))


def test_data_errors_exit_with_1_and_one_line(tmp_path, capsys):
    assert metrics.main(["--gt", str(tmp_path / "gt.txt"), "--est", str(tmp_path / "est.txt")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("python -m jbevo.metrics: error: ") and "gt.txt" in err and "Traceback" not in err
    assert evaluate.main(["--dataset", "kitti", "--sequences", "09", "--out", str(tmp_path / "e")]) == 1
    assert "kitti_root" in capsys.readouterr().err
    assert render.main(["--out", str(tmp_path / "s.npz"), "--kitti-poses", str(tmp_path / "none.txt")]) == 1
    assert "none.txt" in capsys.readouterr().err


def test_a_bug_is_not_taken_for_bad_input():
    """Only the reading of inputs is turned into exit code 1: an error in the computation (here a
    ValueError from the command itself) keeps its traceback."""

    def command(args):
        with common.reading("the inputs"):
            pass
        raise ValueError("an internal inconsistency")

    with pytest.raises(ValueError, match="internal inconsistency"):
        common.run(argparse.ArgumentParser(prog="p"), command, [])
