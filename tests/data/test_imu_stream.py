"""IMU streams to frame blocks: grouping with padding after the real samples, resampling at
sub-interval midpoints, and errors naming what is wrong."""

import numpy as np
import pytest

from jbevo.data.imu_stream import ImuStream, group_blocks, resample_blocks, stream_from_blocks


def _stream(times):
    times = np.asarray(times, float)
    return ImuStream(times, np.stack([times, 2 * times, -times], -1), np.tile([0.0, 0.0, 9.8], (len(times), 1)))


def test_group_blocks_pads_after_the_samples_of_each_frame_interval():
    frames = np.array([0.0, 0.1, 0.2, 0.3])
    stream = _stream([-0.05, 0.02, 0.05, 0.08, 0.15, 0.29, 0.31])  # 0.31 is after the last frame
    times, gyro, _ = group_blocks(stream, frames)
    assert gyro.shape == (4, 3, 3)
    np.testing.assert_allclose(gyro[0, 0], [-0.05, -0.1, 0.05])  # block 0: [t0 - step, t0)
    assert np.all(np.isnan(gyro[0, 1:]))
    np.testing.assert_allclose(gyro[1, :, 0], [0.02, 0.05, 0.08])
    np.testing.assert_allclose(gyro[2, 0, 0], 0.15)
    assert np.all(np.isnan(gyro[2, 1:]))
    assert np.all(np.diff(times.reshape(-1)) > 0)  # pads keep the times increasing
    back = stream_from_blocks(times, gyro, gyro)
    np.testing.assert_allclose(back.times, [-0.05, 0.02, 0.05, 0.08, 0.15, 0.29])


def test_resample_blocks_interpolates_at_sub_interval_midpoints():
    frames = np.array([0.0, 0.1, 0.2])
    stream = _stream(np.linspace(-0.1, 0.2, 31))
    times, gyro, accel = resample_blocks(stream, frames, 4)
    np.testing.assert_allclose(times[1], [0.0125, 0.0375, 0.0625, 0.0875])
    np.testing.assert_allclose(gyro[..., 0], times, atol=1e-12)  # a linear signal is exact
    np.testing.assert_allclose(accel[..., 2], 9.8)
    partial = resample_blocks(_stream([0.0, 0.1, 0.2]), frames, 2)[1]
    assert np.all(np.isnan(partial[0])) and np.all(np.isfinite(partial[1:]))


def test_stream_check_names_the_problem():
    s = _stream([0.0, 0.1])
    with pytest.raises(ValueError, match="increase"):
        s._replace(times=np.array([0.1, 0.0])).check("x")
    with pytest.raises(ValueError, match="gyro must have shape"):
        s._replace(gyro=np.zeros((2, 2))).check("x")
    with pytest.raises(ValueError, match="NaN"):
        s._replace(accel=np.full((2, 3), np.nan)).check("x")
    with pytest.raises(ValueError, match="no samples"):
        _stream([]).check("x")
