"""KITTI and TUM pose files: round trips, frame indices, quaternions, and named errors."""

import numpy as np
import pytest

from jbevo.data import pose_files


def random_poses(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = pose_files.quaternion_to_matrix(q)
    poses[:, :3, 3] = rng.normal(size=(n, 3)) * 100
    return poses


def test_kitti_round_trip_12_and_13_columns(tmp_path):
    poses = random_poses(20)
    pose_files.write_kitti(tmp_path / "a.txt", poses)
    back = pose_files.read_poses(tmp_path / "a.txt")
    np.testing.assert_allclose(back.poses, poses, atol=1e-6)
    np.testing.assert_array_equal(back.frame_index, np.arange(20))
    pose_files.write_kitti(tmp_path / "b.txt", poses[5:], frame_index=np.arange(5, 20))
    assert len((tmp_path / "b.txt").read_text().splitlines()[0].split()) == 13
    late = pose_files.read_kitti(tmp_path / "b.txt")
    np.testing.assert_array_equal(late.frame_index, np.arange(5, 20))
    gt, est, valid = pose_files.match_frames(back, late)
    assert valid.sum() == 15 and not valid[:5].any()
    np.testing.assert_allclose(est[5:], poses[5:], atol=1e-6)


def test_tum_round_trip_and_quaternion_convention(tmp_path):
    poses = random_poses(30, seed=1)
    times = 1.0 + 0.1 * np.arange(30)
    pose_files.write_tum(tmp_path / "t.txt", times, poses)
    back = pose_files.read_poses(tmp_path / "t.txt")
    np.testing.assert_allclose(back.poses, poses, atol=1e-8)
    np.testing.assert_allclose(back.timestamps, times)
    # Scalar-last Hamilton: a 90 deg turn about z is (0, 0, sin 45, cos 45).
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(pose_files.matrix_to_quaternion(rz), [0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    # All four branches of the conversion (w, x, y, z largest) round-trip.
    for q in ([0, 0, 0, 1], [1, 0, 0, 0], [0, 1, 0, 0.01], [0, 0.1, 1, 0]):
        q = np.asarray(q, float) / np.linalg.norm(q)
        r = pose_files.quaternion_to_matrix(q)
        np.testing.assert_allclose(pose_files.quaternion_to_matrix(pose_files.matrix_to_quaternion(r)), r, atol=1e-12)


def test_planar_trajectories_round_trip(tmp_path):
    xy_yaw = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.3], [2.0, 1.5, -3.0]])
    pose_files.write_tum(tmp_path / "p.txt", np.arange(3.0), xy_yaw)
    back = pose_files.read_tum(tmp_path / "p.txt")
    np.testing.assert_allclose(pose_files.to_planar(back.poses), xy_yaw, atol=1e-9)
    np.testing.assert_allclose(back.poses[:, 2, 3], 0.0)


@pytest.mark.parametrize(
    "text, message",
    [
        ("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n", r":2: expected 12 numbers"),
        ("1 0 0 0 0 1 0 x 0 0 1 0\n", r":1: not a number"),
        ("1 0 0 nan 0 1 0 0 0 0 1 0\n", r":1: NaN or inf"),
        ("1 2 3\n", r":1: expected 12 or 13 \(KITTI\) or 8 \(TUM\)"),
        ("", "no poses"),
        ("3 1 0 0 0 0 1 0 0 0 0 1 0\n2 1 0 0 0 0 1 0 0 0 0 1 0\n", r":2: frame indices must increase"),
        ("0.0 0 0 0 0 0 0 1\n0.0 0 0 0 0 0 0 1\n", r":2: timestamps must increase"),
        ("0.0 0 0 0 0 0 0 0\n", r":1: zero-length quaternion"),
    ],
)
def test_malformed_files_name_the_line(tmp_path, text, message):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        pose_files.read_poses(path)


def test_missing_file_and_failed_write_keep_the_old_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="pose file not found"):
        pose_files.read_poses(tmp_path / "nope.txt")
    path = tmp_path / "keep.txt"
    pose_files.write_kitti(path, random_poses(3))
    before = path.read_text()
    bad = random_poses(3)
    bad[1, 0, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        pose_files.write_kitti(path, bad)
    with pytest.raises(ValueError, match="timestamps must have shape"):
        pose_files.write_tum(path, np.arange(2.0), random_poses(3))
    assert path.read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]


def test_matching_rejects_mixed_formats_and_unknown_frames(tmp_path):
    kitti = pose_files.Trajectory(random_poses(5), np.arange(5), None)
    tum = pose_files.Trajectory(random_poses(5), None, np.arange(5.0))
    with pytest.raises(ValueError, match="cannot match"):
        pose_files.match_frames(kitti, tum)
    with pytest.raises(ValueError, match="no frame 7 of the estimate"):
        pose_files.match_frames(kitti, pose_files.Trajectory(random_poses(2), np.array([1, 7]), None))
    # A ground truth of frames 100-104 (13 columns) pairs with an estimate of 102-104.
    late_gt = pose_files.Trajectory(random_poses(5), np.arange(100, 105), None)
    est = random_poses(3, seed=2)
    _, est_full, valid = pose_files.match_frames(late_gt, pose_files.Trajectory(est, np.arange(102, 105), None))
    np.testing.assert_array_equal(valid, [False, False, True, True, True])
    np.testing.assert_allclose(est_full[2:], est)
    with pytest.raises(ValueError, match="no ground truth within"):
        pose_files.match_frames(tum, pose_files.Trajectory(random_poses(1), None, np.array([2.5])))
