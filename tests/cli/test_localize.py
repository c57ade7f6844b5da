"""The BEVO+ command line: train a few steps on a tiny scene, resume, evaluate, and clear errors."""

import json

from jbevo.cli.localize import main
from jbevo.training import checkpoint


def test_train_resume_and_evaluate(tmp_path, capsys):
    out = tmp_path / "run"
    small = ["--kind", "aeroground", "--frames", "48", "--seed", "2"]
    assert main(["train", *small, "--window", "12", "--batch", "2", "--epochs", "1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "29 learnable parameters" in text and "validation after training" in text
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["epochs"] == 1 and metrics["after"]["mean_position_error_m"] < 1.0
    assert (out / "best.ckpt").is_file() and (out / "last.ckpt").is_file()
    assert main(["train", *small, "--window", "12", "--batch", "2", "--epochs", "2", "--out", str(out), "--resume"]) == 0
    assert "resumed" in capsys.readouterr().out
    assert checkpoint.load(out / "last.ckpt")[2]["epoch"] == 2

    ev = tmp_path / "eval"
    args = ["evaluate", *small, "--checkpoint", str(out), "--conditions", "day", "night", "--out", str(ev), "--smooth"]
    assert main(args) == 0
    result = json.loads((ev / "metrics.json").read_text())
    assert len(result["scenes"]) == 2 and result["frames_per_s"] > 0 and result["model"] == "bevo"
    for entry in result["scenes"].values():
        assert set(entry) >= {"BEVO+", "BEVO+ smoothed", "BEVO odometry", "map matching alone"}
        assert entry["BEVO+"]["mean_position_error_m"] < 1.0
        assert entry["BEVO+ smoothed"]["mean_position_error_m"] < 1.0
    name = next(iter(result["scenes"]))
    assert (ev / "plots" / f"{name}.png").is_file() and (ev / "poses" / f"{name}_bevo_plus.txt").is_file()
    assert (ev / "poses" / f"{name}_bevo_plus_smoothed.txt").is_file()

    # The street world, from the street preset's odometry (road view, yaw fusion): it runs, and
    # says which world and model it ran.
    preset = tmp_path / "eval_preset"
    args = ["evaluate", *small, "--model", "street", "--conditions", "day", "--world", "street", "--out", str(preset)]
    assert main(args) == 0
    result = json.loads((preset / "metrics.json").read_text())
    assert result["model"] == "street" and result["world"] == "street" and len(result["scenes"]) == 1
    assert all(e["BEVO+"]["mean_position_error_m"] < 5.0 for e in result["scenes"].values())


def test_errors_name_what_is_wrong_and_exit_with_1(tmp_path, capsys):
    bad = tmp_path / "bad.ckpt"
    bad.write_bytes(b"nope")
    assert main(["evaluate", "--frames", "16", "--checkpoint", str(bad), "--out", str(tmp_path / "e")]) == 1
    assert "not a readable jbevo checkpoint" in capsys.readouterr().err
    from jbevo.models.bevo import Bevo

    checkpoint.save(tmp_path / "odo.ckpt", Bevo.create())
    assert main(["evaluate", "--frames", "16", "--checkpoint", str(tmp_path / "odo.ckpt"), "--out", str(tmp_path / "e")]) == 1
    assert "holds a Bevo, not a BevoPlus" in capsys.readouterr().err
    assert main(["train", "--frames", "16", "--window", "64", "--epochs", "1", "--out", str(tmp_path / "t")]) == 1
    assert "fewer than --window" in capsys.readouterr().err
