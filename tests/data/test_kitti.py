"""KITTI odometry and raw layouts: a tiny exported synthetic sequence read back (the loaders'
fixture), and clear errors for broken folders."""

import numpy as np
import pytest

from jbevo.data import kitti
from jbevo.data.imu_stream import ImuStream
from jbevo.data.synthetic.sequences import procedural_sequence
from jbevo.data.synthetic.world import World
from jbevo.geometry import camera as cam


@pytest.fixture(scope="module")
def seq():
    camera = cam.Camera(60.0, 60.0, 47.5, 15.5, (32, 96), 1.65)
    return procedural_sequence(7, 12, camera=camera, world=World.create("town02", size=256))


def _relative(poses):
    poses = np.asarray(poses, float)
    return np.linalg.inv(poses[0]) @ poses


def test_odometry_round_trip(seq, tmp_path):
    kitti.write_odometry(seq, tmp_path, "03")
    back = kitti.read_odometry(tmp_path, "03")
    np.testing.assert_array_equal(back.images, seq.images)
    np.testing.assert_allclose(back.frame_times, seq.frame_times, rtol=1e-6)
    np.testing.assert_allclose(back.camera.intrinsics, seq.camera.intrinsics, rtol=1e-6)
    np.testing.assert_allclose(_relative(back.poses), _relative(seq.poses), atol=1e-5)
    assert back.gyro.shape == (12, 1, 3) and bool(np.all(np.isnan(back.gyro)))


def test_raw_round_trip(seq, tmp_path):
    drive = tmp_path / "2011_09_26" / "2011_09_26_drive_0001_sync"
    kitti.write_raw(seq, drive)
    back = kitti.read_raw(drive)
    np.testing.assert_array_equal(back.images, seq.images)
    np.testing.assert_allclose(back.frame_times - back.frame_times[0], seq.frame_times - seq.frame_times[0], atol=1e-4)
    np.testing.assert_allclose(back.gyro[:, 0], seq.gyro[:, -1], atol=1e-6)
    np.testing.assert_allclose(back.accel[:, 0], seq.accel[:, -1], atol=1e-5)
    # GPS/INS ground truth through the Mercator projection: millimetres over the drive
    np.testing.assert_allclose(_relative(back.poses)[:, :3, 3], _relative(seq.poses)[:, :3, 3], atol=5e-3)
    np.testing.assert_allclose(_relative(back.poses)[:, :3, :3], _relative(seq.poses)[:, :3, :3], atol=1e-5)


def test_raw_reader_groups_100_hz_oxts_into_frame_blocks(seq, tmp_path):
    drive = tmp_path / "d" / "drive_sync"
    kitti.write_raw(seq, drive)
    # Re-time the OXTS records as three samples per frame interval by duplicating them.
    data = sorted((drive / "oxts" / "data").glob("*.txt"))
    times = kitti._timestamps(drive / "image_00" / "timestamps.txt")
    for f in data:
        f.unlink()
    stamps = []
    for i, t in enumerate(times):
        for j, dt in enumerate((-0.09, -0.06, -0.03)):
            n = 3 * i + j
            (drive / "oxts" / "data" / f"{n:010d}.txt").write_text(" ".join(["49.0", "8.4"] + ["0"] * 28))
            stamps.append(kitti._format_time(t + dt))
    (drive / "oxts" / "timestamps.txt").write_text("\n".join(stamps) + "\n")
    back = kitti.read_raw(drive)
    assert back.gyro.shape == (12, 3, 3)
    assert bool(np.all(np.isfinite(back.gyro)))


def test_errors_name_the_file(seq, tmp_path):
    with pytest.raises(FileNotFoundError, match="sequences"):
        kitti.read_odometry(tmp_path, "00")
    kitti.write_odometry(seq, tmp_path, "00")
    times = tmp_path / "sequences" / "00" / "times.txt"
    times.write_text("\n".join(times.read_text().splitlines()[:-1]) + "\n")
    with pytest.raises(ValueError, match="12 images but 11 times"):
        kitti.read_odometry(tmp_path, "00")
    kitti.write_odometry(seq, tmp_path, "00")
    (tmp_path / "poses" / "00.txt").write_text("1 2 3\n")
    with pytest.raises(ValueError, match="expected 12 numbers"):
        kitti.read_odometry(tmp_path, "00")
    drive = tmp_path / "x" / "drive"
    kitti.write_raw(seq, drive)
    stamps = drive / "oxts" / "timestamps.txt"
    lines = stamps.read_text().splitlines()
    stamps.write_text("\n".join([lines[1], lines[0], *lines[2:]]) + "\n")
    with pytest.raises(ValueError, match="increasing"):
        kitti.read_raw(drive)


def test_frames_interpolated_over_a_dropout_are_found():
    rng = np.random.default_rng(0)
    frames, per = 30, 10
    rows = np.cumsum(rng.normal(0.0, 0.03, (per * (frames - 1) + 1, 6)), axis=0) + [0.0, 0.0, 0.0, 0.0, 0.0, 9.8]
    # A dropout from frame 8 to frame 14, filled by a straight line as the published file does.
    a, b = 8 * per, 14 * per
    rows[a : b + 1] = rows[a] + np.linspace(0.0, 1.0, b - a + 1)[:, None] * (rows[b] - rows[a])
    stream = ImuStream(np.arange(len(rows)) * 0.01, rows[:, 3:], rows[:, :3])
    np.testing.assert_array_equal(np.flatnonzero(kitti.interpolated_frames(stream, per)), np.arange(9, 14))
    np.testing.assert_allclose(kitti.dropout_spans(stream, per), [[a * 0.01, b * 0.01]])
    np.testing.assert_array_equal(kitti.dropout_frames(kitti.interpolated_frames(stream, per)), [[9, 13]])
    assert kitti.dropout_frames(np.zeros(5, bool)).shape == (0, 2)
    # Without the dropout, the samples' own noise keeps every frame off the line.
    noisy = rows + rng.normal(0.0, 0.03, rows.shape)
    assert not kitti.interpolated_frames(ImuStream(stream.times, noisy[:, 3:], noisy[:, :3]), per).any()
    assert kitti.dropout_spans(ImuStream(stream.times, noisy[:, 3:], noisy[:, :3]), per).shape == (0, 2)
    # One or two frames have no interior frame to test.
    for frames in (1, 2):
        short = ImuStream(*(field[: per * (frames - 1) + 1] for field in stream))
        np.testing.assert_array_equal(kitti.interpolated_frames(short, per), np.zeros(frames, bool))
    with pytest.raises(ValueError, match="not 7 per frame"):
        kitti.interpolated_frames(stream, 7)
    with pytest.raises(ValueError, match="at least 1"):
        kitti.interpolated_frames(stream, 0)


def test_a_reader_marks_a_dropout_missing_when_asked(seq, tmp_path):
    import scipy.io

    kitti.write_odometry(seq, tmp_path, "03")
    rng = np.random.default_rng(1)
    per, n = 10, seq.num_frames
    rows = np.cumsum(rng.normal(0.0, 0.03, (per * (n - 1) + 1, 6)), axis=0) + [0.0, 0.0, 9.8, 0.0, 0.0, 0.0]
    a, b = 3 * per, 7 * per  # a line from frame 3's sample to frame 7's
    rows[a : b + 1] = rows[a] + np.linspace(0.0, 1.0, b - a + 1)[:, None] * (rows[b] - rows[a])
    scipy.io.savemat(tmp_path / "03.mat", {"imu_data_interp": rows})
    published = kitti.read_odometry(tmp_path, "03", imu=tmp_path)
    missing = kitti.read_odometry(tmp_path, "03", imu=tmp_path, imu_dropouts="missing")
    t = np.asarray(published.frame_times, float)
    spans = kitti.dropout_spans(kitti.read_kitti_imu(tmp_path / "03.mat", t))
    np.testing.assert_allclose(spans, [[t[3], t[7]]])
    np.testing.assert_array_equal(np.asarray(missing.gyro), np.asarray(kitti.without_dropouts(published, spans).gyro))
    # Blocks 5-7 lie wholly on the line (block k: the rows from frame k - 1 to frame k).
    wholly = np.isnan(np.asarray(missing.gyro)).all((1, 2))
    np.testing.assert_array_equal(np.flatnonzero(wholly), [0, 5, 6, 7])
    with pytest.raises(ValueError, match="imu_dropouts must be one of"):
        kitti.read_odometry(tmp_path, "03", imu=tmp_path, imu_dropouts="skip")


def test_rows_on_a_dropout_line_are_marked_missing(seq):
    # A line from frame 2 to frame 6: the rows strictly between go, the knots' stay.
    frame_t, times = np.asarray(seq.frame_times, float), np.asarray(seq.imu_times, float)
    span = np.array([[frame_t[2], frame_t[6]]])
    for offset in (0.0, 0.05):
        marked = kitti.without_dropouts(seq, span, time_offset_s=offset)
        gyro, accel = np.asarray(marked.gyro), np.asarray(marked.accel)
        expected = (times - offset > frame_t[2]) & (times - offset < frame_t[6])
        assert expected.sum() > 30
        np.testing.assert_array_equal(np.isnan(gyro).any(-1), expected)
        np.testing.assert_array_equal(np.isnan(accel).any(-1), expected)
        np.testing.assert_array_equal(kitti.on_dropout_lines(times, span, offset), expected)
        np.testing.assert_array_equal(gyro[~expected], np.asarray(seq.gyro)[~expected])
        np.testing.assert_array_equal(np.asarray(marked.images), np.asarray(seq.images))
    # Read as published (no offset), the blocks wholly on the line are those after the first knot's.
    wholly = np.isnan(np.asarray(kitti.without_dropouts(seq, span).gyro)).all((1, 2))
    np.testing.assert_array_equal(np.flatnonzero(wholly), [4, 5, 6])
    # No span, nothing marked.
    np.testing.assert_array_equal(np.asarray(kitti.without_dropouts(seq, np.zeros((0, 2))).gyro), np.asarray(seq.gyro))
    for bad in (span[0], span[:, ::-1]):
        with pytest.raises(ValueError, match="spans must be"):
            kitti.without_dropouts(seq, bad)
        with pytest.raises(ValueError, match="spans must be"):
            kitti.on_dropout_lines(times, bad)


def test_a_knot_stamped_in_float32_stays_a_knot():
    # Late in a long drive a float32 stamp of a knot lies up to ~30 microseconds off the float64
    # knot, inside the span: it is still the recorded sample, not the line.
    knots = np.array([[1234.5671, 1235.8123]])
    stamps = np.float32(knots[0, 0] + 0.01 * np.arange(0, 126))
    assert float(stamps[0]) > knots[0, 0]  # rounded into the span
    marked = kitti.on_dropout_lines(stamps, knots)
    assert not marked[0] and marked[1:125].all() and not marked[125]
