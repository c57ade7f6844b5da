"""Training windows: windows cut from the sequences, or the whole sequences batched."""

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
    batch = training_windows(seqs, 8)  # stride 4: 2 + 2 windows of the 12-frame drives, 1 of the 9
    assert batch.images.shape[:2] == (5, 8)
    with pytest.raises(ValueError, match="no sequence has 20 frames"):
        training_windows(seqs, 20)


def test_window_zero_batches_the_whole_sequences(seqs):
    batch = training_windows(seqs[:2], 0)
    assert batch.images.shape[:2] == (2, 12)
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
