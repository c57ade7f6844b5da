"""Training windows: windows cut from the sequences (sliced on demand, not copied), or the whole
sequences batched."""

import numpy as np
import pytest

from jbevo.data.synthetic import World, procedural_sequence
from jbevo.geometry import Camera
from jbevo.training.windows import training_windows

CAMERA = Camera(60.0, 60.0, 47.5, 15.5, (32, 96), 1.65)


@pytest.fixture(scope="module")
def seqs():
    world = World.create("town01", size=256)
    return [procedural_sequence(s, n, camera=CAMERA, world=world) for s, n in ((0, 12), (1, 12), (2, 9))]


def test_windows_of_every_long_enough_sequence(seqs):
    windows = training_windows(seqs, 8)  # stride 4: 2 + 2 windows of the 12-frame drives, 1 of the 9
    assert len(windows) == 5 and windows.all().images.shape[:2] == (5, 8)
    assert windows.drive_index.tolist() == [0, 0, 1, 1, 2] and windows.starts.tolist() == [0, 4, 0, 4, 0]
    with pytest.raises(ValueError, match="no sequence has 20 frames"):
        training_windows(seqs, 20)


def test_a_batch_holds_the_frames_of_its_windows_and_the_drives_are_not_copied(seqs):
    windows = training_windows(seqs, 8, stride=2)
    batch = windows.batch([4, 0])  # drive 1 from frame 2 (windows 0-2 start at 0, 2, 4 of drive 0), drive 0 from 0
    np.testing.assert_array_equal(batch.images[0], np.asarray(seqs[1].images[2:10]))
    np.testing.assert_array_equal(batch.gyro[1], np.asarray(seqs[0].gyro[:8]))
    np.testing.assert_array_equal(batch.poses[0], np.asarray(seqs[1].poses[2:10]))
    assert batch.camera.intrinsics.shape == (2, 3, 3)
    # Each drive is held once, however many windows overlap it, and not copied from the loader.
    assert all(np.shares_memory(d.images, np.asarray(s.images)) for d, s in zip(windows.drives, seqs, strict=True))
    held = sum(d.images.nbytes for d in windows.drives)
    assert windows.all().images.nbytes > 1.6 * held  # 7 windows of 8 frames: 56 frames of 33
    with pytest.raises(IndexError, match="within"):
        windows.batch([len(windows)])


def test_window_zero_batches_the_whole_sequences(seqs):
    windows = training_windows(seqs[:2], 0)
    assert windows.all().images.shape[:2] == (2, 12)
    with pytest.raises(ValueError, match="sequence 2 has"):
        training_windows(seqs, 0)


def test_a_runtime_check_inside_the_model_ends_training_as_divergence():
    import equinox as eqx
    import jax.numpy as jnp
    import numpy as np

    from jbevo.training.loop import TrainingDiverged, run_epoch

    @eqx.filter_jit
    def step(params, opt_state, batch):
        return params, opt_state, eqx.error_if(jnp.sum(batch), jnp.any(batch > 0), "register: image a contains NaN or inf")

    with pytest.raises(TrainingDiverged, match=r"epoch 2, step 0 \(register: image a contains NaN or inf\)"):
        run_epoch(step, 0, 0, jnp.ones((4, 2)), 2, np.random.default_rng(0), "epoch 2")
