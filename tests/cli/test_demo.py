import json

import pytest

from jbevo.cli import demo


def test_demo_learns_noise_and_writes_metrics(tmp_path):
    args = demo.build_parser().parse_args(
        ["--steps", "100", "--train", "8", "--val", "8", "--iterations", "60", "--out", str(tmp_path)]
    )
    metrics = demo.demo(args)
    assert metrics["after"]["position_rmse_m"] < 0.7 * metrics["before"]["position_rmse_m"]
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["after"] == metrics["after"]
    assert not list(tmp_path.glob("*.tmp"))


def test_demo_rejects_bad_arguments():
    with pytest.raises(SystemExit) as exit:
        demo.main(["--steps", "0"])
    assert exit.value.code == 2
