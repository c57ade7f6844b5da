"""The commands' datasets: a share of a list of KITTI-style drives renders each drive as the
whole list does (its seed is its place in the whole list); a world is named or given by its
settings."""

import dataclasses

import numpy as np
import pytest

from jbevo.data.catalog import load_sequences
from jbevo.data.synthetic.street import STREET


def test_a_share_renders_its_drives_as_the_whole_list(reference_data):
    poses = reference_data / "kitti_odom" / "gt_poses"
    whole = load_sequences("kitti-synthetic", ["04", "05", "06"], 8, poses, seed=7)
    share = load_sequences("kitti-synthetic", ["04", "06"], 8, poses, seed=7, positions=[0, 2])
    for a, b in zip(share, [whole[0], whole[2]], strict=True):
        np.testing.assert_array_equal(np.asarray(a.images), np.asarray(b.images))
        np.testing.assert_array_equal(np.asarray(a.gyro), np.asarray(b.gyro))
    assert not np.array_equal(
        np.asarray(share[1].gyro), np.asarray(load_sequences("kitti-synthetic", ["06"], 8, poses, seed=7)[0].gyro)
    )
    with pytest.raises(ValueError, match="1 positions for 2 sequence names"):
        load_sequences("kitti-synthetic", ["04", "06"], 8, poses, positions=[0])


def test_a_world_is_named_or_given_by_its_settings(reference_data):
    poses = reference_data / "kitti_odom" / "gt_poses"
    named = load_sequences("kitti-synthetic", ["04"], 4, poses, world="street")[0]
    given = load_sequences("kitti-synthetic", ["04"], 4, poses, world=STREET)[0]
    np.testing.assert_array_equal(np.asarray(named.images), np.asarray(given.images))
    level = load_sequences("kitti-synthetic", ["04"], 4, poses, world=dataclasses.replace(STREET, slopes=False))[0]
    assert not np.array_equal(np.asarray(level.accel), np.asarray(given.accel))  # the grade reaches the IMU
    flat = load_sequences("kitti-synthetic", ["04"], 4, poses, world=None)[0]
    np.testing.assert_array_equal(
        np.asarray(flat.images), np.asarray(load_sequences("kitti-synthetic", ["04"], 4, poses)[0].images)
    )


def test_marking_imu_dropouts_needs_the_real_imu():
    with pytest.raises(ValueError, match="needs kitti_imu"):
        load_sequences("synthetic", ["0"], frames=2, imu_dropouts="missing")
    with pytest.raises(ValueError, match="imu_dropouts must be one of"):
        load_sequences("synthetic", ["0"], frames=2, imu_dropouts="dropped")
