"""The synthetic world: determinism, periodicity, the packed pyramid and its filtering."""

import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.world import TOWNS, Town, World, make_tile


@pytest.fixture(scope="module")
def world():
    return World.create("town01", size=256, resolution=0.04)


def test_tile_is_deterministic_by_seed_and_differs_between_towns():
    a = make_tile(TOWNS["town01"], 128)
    np.testing.assert_array_equal(a, make_tile(TOWNS["town01"], 128))
    assert np.abs(a - make_tile(TOWNS["town02"], 128)).mean() > 0.05
    assert 0.0 <= a.min() and a.max() <= 1.0 and a.std() > 0.05


def test_level_zero_sample_reproduces_the_tile_at_texel_centres(world):
    tile = make_tile(TOWNS["town01"], 256)
    r, c = np.meshgrid(np.arange(0, 256, 7), np.arange(0, 256, 5), indexing="ij")
    got = world.sample(jnp.asarray(c * 0.04), jnp.asarray(r * 0.04), 0.0)
    np.testing.assert_allclose(np.asarray(got), tile[r, c], atol=1 / 255)


def test_every_pyramid_level_matches_a_box_filtered_tile(world):
    tile = make_tile(TOWNS["town01"], 256).astype(np.float64)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-50, 50, 500), rng.uniform(-50, 50, 500)
    for k in range(len(world.sizes)):
        level = tile.reshape(256 >> k, 1 << k, 256 >> k, 1 << k).mean(axis=(1, 3))
        n = level.shape[0]
        # independent bilinear sampling with wrap at level-k texel coordinates
        u = x / (0.04 * 2**k) - 0.5 + 0.5 / 2**k
        v = y / (0.04 * 2**k) - 0.5 + 0.5 / 2**k
        iu, iv = np.floor(u).astype(int), np.floor(v).astype(int)
        fu, fv = u - iu, v - iv
        t = lambda dr, dc, level=level, iv=iv, iu=iu, n=n: level[(iv + dr) % n, (iu + dc) % n]
        expected = (t(0, 0) * (1 - fu) + t(0, 1) * fu) * (1 - fv) + (t(1, 0) * (1 - fu) + t(1, 1) * fu) * fv
        got = world._level(*(jnp.asarray(a, jnp.float32) for a in ((x / 0.04) % 256, (y / 0.04) % 256)), jnp.full(500, k))
        np.testing.assert_allclose(np.asarray(got), expected, atol=2.5 / 255, err_msg=f"level {k}")


def test_world_is_periodic_and_filtering_removes_detail(world):
    x = jnp.linspace(0.0, 7.0, 200)
    y = jnp.full_like(x, 3.3)
    np.testing.assert_allclose(world.sample(x, y), world.sample(x + world.period, y - 2 * world.period), atol=1e-3)
    sharp = world.top_down((0.0, 0.0), (64, 64), 0.04)
    blurred = world.sample(jnp.arange(64) * 0.04, jnp.zeros(64), 0.64)
    assert float(jnp.std(jnp.diff(blurred))) < 0.3 * float(jnp.std(jnp.diff(sharp[0])))


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="unknown town"):
        World.create("nowhere")
    with pytest.raises(ValueError, match="power of two"):
        World.create(Town(), size=100)
    with pytest.raises(ValueError, match="in \\[0, 1\\]"):
        World.from_tile(np.full((32, 32), 2.0), 0.1)
