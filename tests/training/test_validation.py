"""Validation scores models the way they are scored, and compiles the recursion once: every
epoch's model has the same structure, so the second validation compiles nothing."""

import contextlib

import equinox as eqx
import jax
import jax.numpy as jnp
import pytest

from jbevo.data.synthetic import World, procedural_sequence
from jbevo.eval.scores import SHORT_SEGMENTS
from jbevo.geometry import BevGrid, Camera
from jbevo.models import Bevo
from jbevo.training.validation import validate

CAMERA = Camera(60.0, 60.0, 47.5, 15.5, (32, 96), 1.65)


@contextlib.contextmanager
def counting_compilations():
    count = []

    def listener(name, seconds, **kwargs):
        if name == "/jax/core/compile/backend_compile_duration":
            count.append(name)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield count
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


@pytest.fixture(scope="module")
def seqs():
    world = World.create("town01", size=256)
    return [procedural_sequence(seed, 10, camera=CAMERA, world=world) for seed in (0, 1)]


@pytest.mark.parametrize("window", [0, 5])
def test_the_second_validation_compiles_nothing(seqs, window):
    model = Bevo.create(BevGrid(0.2, (32, 32), near=4.0))
    first = validate(model, seqs, SHORT_SEGMENTS, window)
    trained = eqx.tree_at(lambda m: m.dpc.highpass, model, jnp.float32(0.6))  # the next epoch's model
    with counting_compilations() as compilations:
        second = validate(trained, seqs, SHORT_SEGMENTS, window)
    assert compilations == []
    assert second["motion_rmse_m"] != first["motion_rmse_m"]
