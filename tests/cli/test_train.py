"""python -m jbevo.train and python -m jbevo.evaluate on a tiny built-in dataset: metrics before
and after, checkpoints, --resume, and the evaluation's pose files, plots and metrics (also
sharded over four CPU devices)."""

import json
import os
import subprocess
import sys

import pytest

from jbevo.cli import evaluate, train

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


def test_evaluate_writes_poses_plots_and_metrics(run_dir, tmp_path):
    out = tmp_path / "eval"
    args = ["--sequences", "2", "--frames", "16", "--grid", "0.1", "64", "7.5", "--out", str(out)]
    assert evaluate.main(["--checkpoint", str(run_dir), *args]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["per_sequence"]) == {"synthetic_1000", "synthetic_1001"}
    assert metrics["overall"]["frames_per_s"] > 0
    assert (out / "poses" / "synthetic_1000.txt").read_text().count("\n") == 16
    assert (out / "plots" / "synthetic_1001.png").stat().st_size > 1000


def test_evaluate_shards_over_four_cpu_devices(tmp_path):
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    out = tmp_path / "sharded"
    cmd = [
        sys.executable,
        "-m",
        "jbevo.evaluate",
        "--sequences",
        "3",
        "--frames",
        "8",
        "--grid",
        "0.1",
        "64",
        "7.5",
        "--out",
        str(out),
    ]
    result = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert len(metrics["devices"]) == 4 and len(metrics["per_sequence"]) == 3


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
