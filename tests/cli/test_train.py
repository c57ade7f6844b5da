"""python -m jbevo.train and python -m jbevo.evaluate on a tiny built-in dataset: metrics before
and after, checkpoints, --resume, and the evaluation's pose files, plots and metrics; both as
two processes of one job (jax.distributed over gloo on localhost; the evaluation's process 0
sharding its share over two CPU devices), equal to the one-process run to round-off."""

import json
import shutil

import equinox as eqx
import jax
import numpy as np
import pytest

from jbevo.cli import evaluate, train
from jbevo.models.bevo import Bevo
from jbevo.training import checkpoint
from tests.helpers import run_processes

TINY = [
    "--sequences",
    "2",
    "--frames",
    "24",
    "--window",
    "12",
    "--start",
    "warm",
    "--val-window",
    "12",
    "--batch",
    "2",
    "--grid",
    "0.1",
    "64",
    "7.5",
]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    assert train.main([*TINY, "--epochs", "1", "--out", str(out)]) == 0
    shutil.copy(out / "last.ckpt", out / "epoch1.ckpt")  # --resume below trains on
    shutil.copy(out / "metrics.json", out / "epoch1.json")
    return out


EVALUATE = ["--sequences", "3", "--frames", "16", "--grid", "0.1", "64", "7.5"]


@pytest.fixture(scope="module")
def evaluation(run_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("eval")
    assert evaluate.main(["--checkpoint", str(run_dir / "epoch1.ckpt"), *EVALUATE, "--out", str(out)]) == 0
    return out


def test_train_writes_metrics_and_checkpoints(run_dir, capsys):
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["learnable_parameters"] == 14 and metrics["epochs"] == 1
    for key in ("ate_m", "motion_rmse_m", "yaw_rmse_deg"):
        assert metrics["before"][key] >= 0 and metrics["after"][key] >= 0
    # 24 frames hold no 10 m segment: no t_err, not a zero
    assert metrics["before"]["segments"] == 0 and metrics["before"]["t_err_pct"] is None
    assert (run_dir / "best.ckpt").is_file() and (run_dir / "last.ckpt").is_file()


def test_the_default_run_trains_and_validates_whole_drives_from_a_cold_start(tmp_path, capsys):
    """The defaults train on whole drives started cold and select on whole validation drives run
    the same way; the hand-set parameters are the first candidate."""
    out = tmp_path / "whole"
    assert (
        train.main(["--sequences", "2", "--frames", "16", "--epochs", "2", "--grid", "0.1", "64", "7.5", "--out", str(out)]) == 0
    )
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["validation"] == "whole sequences, cold start"
    assert metrics["best_epoch"] in (0, 1, 2) and len(metrics["history"]) == 2
    text = capsys.readouterr().out
    assert f"best checkpoint, epoch {metrics['best_epoch']}" in text
    assert ("best.ckpt holds them" in text) == (metrics["best_epoch"] == 0)
    best_t_err = min([metrics["before"]["ate_m"]] + [h["val_ate_m"] for h in metrics["history"]])
    assert metrics["after"]["ate_m"] == best_t_err  # 16 frames hold no segment: ATE selects


def test_resume_continues_from_the_last_epoch(run_dir, capsys):
    assert train.main([*TINY, "--epochs", "2", "--out", str(run_dir), "--resume"]) == 0
    assert "resumed" in capsys.readouterr().out
    assert json.loads((run_dir / "metrics.json").read_text())["epochs"] == 2


def test_resume_from_a_corrupt_checkpoint_fails_clearly(tmp_path, capsys):
    (tmp_path / "last.ckpt").write_bytes(b"garbage")
    assert train.main([*TINY, "--epochs", "1", "--out", str(tmp_path), "--resume"]) == 1
    err = capsys.readouterr().err
    assert "last.ckpt is not a readable jbevo checkpoint" in err and "Traceback" not in err


def test_the_street_model_trains_in_the_street_world_and_evaluates(tmp_path, capsys):
    """``--model street --forward-fusion`` trains the street preset's parts (the road view, the yaw
    fusion) and the forward fusion's, and its checkpoint brings them back to ``evaluate``;
    ``--world street`` renders the street world. Hand-set, ``evaluate`` takes the same options."""
    out = tmp_path / "street"
    args = [*TINY, "--epochs", "1", "--model", "street", "--forward-fusion", "--world", "street", "--out", str(out)]
    assert train.main(args) == 0
    model = checkpoint.load_model(out / "last.ckpt", Bevo)
    assert model.road is not None and model.yaw_fusion is not None and model.forward is not None
    assert json.loads((out / "metrics.json").read_text())["learnable_parameters"] > 14 + 3
    ev = tmp_path / "street_eval"
    assert evaluate.main(["--checkpoint", str(out), *EVALUATE, "--world", "street", "--out", str(ev)]) == 0
    metrics = json.loads((ev / "metrics.json").read_text())
    assert (
        metrics["road_view"] and metrics["forward_fusion"] and metrics["world"] == "street" and metrics["overall"]["ate_m"] >= 0
    )
    for options, fused in (([], False), (["--forward-fusion"], True)):
        hand = tmp_path / f"street_hand_set_{fused}"
        assert evaluate.main([*EVALUATE, "--model", "street", *options, "--out", str(hand)]) == 0
        metrics = json.loads((hand / "metrics.json").read_text())
        assert metrics["road_view"] and metrics["forward_fusion"] is fused


def test_evaluate_writes_poses_plots_and_metrics(evaluation):
    metrics = json.loads((evaluation / "metrics.json").read_text())
    assert list(metrics["per_sequence"]) == ["synthetic_1000", "synthetic_1001", "synthetic_1002"]
    assert metrics["overall"]["frames_per_s"] > 0 and metrics["processes"] == 1
    assert (evaluation / "poses" / "synthetic_1000.txt").read_text().count("\n") == 16
    assert (evaluation / "plots" / "synthetic_1001.png").stat().st_size > 1000


def test_two_processes_train_as_one(run_dir, tmp_path):
    out = tmp_path / "two"
    results = run_processes("jbevo.train", [*TINY, "--epochs", "1", "--out", str(out)])
    # Process 0 reports; the other prints nothing of its own (gloo may say it connected).
    assert "validation after training" in results[0].stdout and "validation" not in results[1].stdout
    one, two = (json.loads(path.read_text()) for path in (run_dir / "epoch1.json", out / "metrics.json"))
    assert (one["processes"], one["devices"], two["processes"], two["devices"]) == (1, 1, 2, 2)
    assert two["history"][0]["loss"] == pytest.approx(one["history"][0]["loss"], rel=1e-5)
    models = [checkpoint.load_model(path, Bevo) for path in (run_dir / "epoch1.ckpt", out / "last.ckpt")]
    hand_set = Bevo.create(models[0].grid, 0.01)
    leaves = [jax.tree_util.tree_leaves(eqx.filter(m, eqx.is_inexact_array)) for m in (*models, hand_set)]
    assert not all(np.allclose(x, y) for x, y in zip(leaves[0], leaves[2], strict=True))  # it trained
    for x, y in zip(leaves[1], leaves[0], strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-4, atol=1e-6)


def test_two_processes_evaluate_as_one(run_dir, evaluation, tmp_path):
    """Process 0 with two devices, process 1 with one: the trajectories gather all the same."""
    out = tmp_path / "two"
    run_processes("jbevo.evaluate", ["--checkpoint", str(run_dir / "epoch1.ckpt"), *EVALUATE, "--out", str(out)], (2, 1))
    one, two = (json.loads((d / "metrics.json").read_text()) for d in (evaluation, out))
    assert (two["processes"], len(two["devices"])) == (2, 3)
    assert list(two["per_sequence"]) == list(one["per_sequence"])  # all three, in order
    for name in one["per_sequence"]:
        assert two["per_sequence"][name]["ate_m"] == pytest.approx(one["per_sequence"][name]["ate_m"], rel=1e-4)
        poses = [np.loadtxt(d / "poses" / f"{name}.txt") for d in (evaluation, out)]
        np.testing.assert_allclose(poses[1], poses[0], atol=1e-4)
    assert two["overall"]["ate_m"] == pytest.approx(one["overall"]["ate_m"], rel=1e-4)


def test_kitti_defaults_select_on_08_and_never_on_a_training_sequence(tmp_path, capsys):
    args = train.build_parser().parse_args(["--dataset", "kitti"])
    assert args.val == ["08"] and "08" not in args.train and not {"09", "10"} & set(args.train + args.val)
    argv = ["--dataset", "kitti", "--kitti-root", str(tmp_path), "--train", "00", "08", "--val", "08"]
    assert train.main(argv) == 1
    assert "sequences 08 would both train and select the checkpoint" in capsys.readouterr().err


def test_kitti_without_imu_is_refused_not_filtered_on_zeros(tmp_path, capsys):
    from jbevo.data import kitti
    from jbevo.data.synthetic.sequences import procedural_sequence
    from jbevo.data.synthetic.world import World
    from jbevo.geometry import camera as cam

    seq = procedural_sequence(
        7, 6, camera=cam.Camera(60.0, 60.0, 47.5, 15.5, (32, 96), 1.65), world=World.create("town02", size=256)
    )
    for name in ("00", "08"):
        kitti.write_odometry(seq, tmp_path, name)
    assert train.main(["--dataset", "kitti", "--kitti-root", str(tmp_path), "--train", "00", "--val", "08"]) == 1
    err = capsys.readouterr().err
    assert "sequences 00, 08 hold no IMU samples" in err and "--kitti-imu" in err
    argv = ["--dataset", "kitti", "--kitti-root", str(tmp_path), "--sequences", "00", "--out", str(tmp_path / "e")]
    assert evaluate.main(argv) == 1
    assert "--attitude zero|truth" in capsys.readouterr().err
    missing = argv + ["--kitti-imu", str(tmp_path / "imu")]
    assert evaluate.main(missing) == 1
    assert "missing IMU file" in capsys.readouterr().err


def test_the_imu_dropouts_option_reaches_the_readers(monkeypatch, capsys):
    assert train.build_parser().parse_args([]).imu_dropouts == "published"
    assert evaluate.build_parser().parse_args(["--imu-dropouts", "missing"]).imu_dropouts == "missing"
    with pytest.raises(SystemExit):
        train.build_parser().parse_args(["--imu-dropouts", "dropped"])
    assert "invalid choice" in capsys.readouterr().err
    asked = []

    def load(dataset, names, **options):
        asked.append(options["imu_dropouts"])
        raise FileNotFoundError("stop here")

    monkeypatch.setattr(train, "load_sequences", load)
    args = train.build_parser().parse_args(["--dataset", "kitti", "--kitti-root", "x", "--imu-dropouts", "missing"])
    with pytest.raises(train.common.CommandError):
        train.load_datasets(args)
    assert asked == ["missing"]
