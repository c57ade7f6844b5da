"""Figures are written as valid PNGs, atomically, from poses and planar trajectories."""

import numpy as np

from jbevo.data import pose_files
from jbevo.eval import plots


def is_png(path):
    return path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_figures_are_written(tmp_path):
    t = np.linspace(0, 2 * np.pi, 100)
    planar = np.stack([np.cos(t) * 50, np.sin(t) * 50, t], 1)
    poses = pose_files.planar_to_poses(planar + 1.0)
    plots.trajectory_top_view(tmp_path / "top.png", planar, {"a": poses, "b": planar * 1.02}, plane=(0, 1))
    plots.segment_errors(tmp_path / "seg.png", [100, 200, 300], {"a": [1.0, 0.9, 0.8]}, {"a": [0.3, 0.2, 0.2]})
    plots.error_over_time(tmp_path / "time.png", t, {"position [m]": np.abs(np.sin(t))})
    for name in ("top.png", "seg.png", "time.png"):
        assert is_png(tmp_path / name)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seg.png", "time.png", "top.png"]
