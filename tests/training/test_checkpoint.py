"""Checkpoints: round trip of the learned values and the optimizer state, and clear errors."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jbevo.geometry.bev_grid import BevGrid
from jbevo.models.bevo import Bevo
from jbevo.training import checkpoint


def test_round_trip_keeps_values_structure_and_optimizer_state(tmp_path):
    model = Bevo.create(BevGrid(0.2, (32, 32), near=6.0), attitude_source="accel")
    model = eqx.tree_at(lambda m: m.dpc.highpass, model, jnp.float32(0.77))
    opt = optax.adam(1e-2)
    state = opt.init(eqx.filter(model, eqx.is_inexact_array))
    path = tmp_path / "a.ckpt"
    checkpoint.save(path, model, state, {"epoch": 3})
    back, back_state, progress = checkpoint.load(path, opt.init(eqx.filter(Bevo.create(), eqx.is_inexact_array)))
    assert progress == {"epoch": 3}
    assert back.grid == model.grid and back.attitude_source == "accel"
    assert float(back.dpc.highpass) == pytest.approx(0.77)
    np.testing.assert_allclose(back.attitude.motion_noise.log_std, model.attitude.motion_noise.log_std)
    assert int(back_state[0].count) == 0


def test_round_trip_keeps_the_band_geometry(tmp_path):
    model = Bevo.create(BevGrid(0.2, (32, 32), near=6.0), bands=True)
    model = eqx.tree_at(lambda m: m.bands.log_yaw_gain, model, jnp.float32(0.5))
    checkpoint.save(tmp_path / "b.ckpt", model)
    back, _, _ = checkpoint.load(tmp_path / "b.ckpt")
    assert back.bands is not None and float(back.bands.log_yaw_gain) == pytest.approx(0.5)
    plain = tmp_path / "plain.ckpt"
    checkpoint.save(plain, Bevo.create(BevGrid(0.2, (32, 32), near=6.0)))
    assert checkpoint.load(plain)[0].bands is None


def test_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        checkpoint.load(tmp_path / "missing.ckpt")
    bad = tmp_path / "bad.ckpt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="not a readable jbevo checkpoint"):
        checkpoint.load(bad)
    good = tmp_path / "good.ckpt"
    checkpoint.save(good, Bevo.create())
    truncated = tmp_path / "truncated.ckpt"
    truncated.write_bytes(good.read_bytes()[:-300])
    with pytest.raises(ValueError, match=str(truncated.name)):
        checkpoint.load(truncated)
    with np.load(good) as data:
        arrays = dict(data)
    arrays["config"] = np.array('{"format": 99}')
    with open(tmp_path / "future.ckpt", "wb") as f:
        np.savez(f, **arrays)
    with pytest.raises(ValueError, match="incompatible"):
        checkpoint.load(tmp_path / "future.ckpt")


def test_bevo_plus_round_trip(tmp_path):
    from jbevo.models.bevo_plus import BevoPlus

    odometry = Bevo.create(BevGrid(0.05, (32, 32), near=3.0), gyro_window=0.03)
    model = BevoPlus.create(odometry, BevGrid(0.1, (32, 32), near=3.0), min_confidence=0.1, gyro_yaw=False)
    model = eqx.tree_at(lambda m: m.fix_log_std, model, jnp.array([-1.0, -2.0, -3.0], jnp.float32))
    path = tmp_path / "plus.ckpt"
    checkpoint.save(path, model)
    back, _, _ = checkpoint.load(path)
    assert isinstance(back, BevoPlus) and back.map_grid == model.map_grid and back.odometry.grid == odometry.grid
    assert back.odometry.gyro_window == pytest.approx(0.03) and back.min_confidence == 0.1 and not back.gyro_yaw
    np.testing.assert_allclose(back.fix_log_std, [-1.0, -2.0, -3.0])


def test_every_static_setting_of_a_non_default_model_round_trips(tmp_path):
    """Every field comes back, the static ones included (DPC's radii, taper, peak window and
    padding, the feathering widths, the grids): the reloaded model equals the saved one."""
    import dataclasses

    from jbevo.models.bevo_plus import BevoPlus

    odometry = Bevo.create(
        BevGrid(0.05, (32, 48), near=3.0),
        gyro_window=0.03,
        bands=True,
        n_radii=32,
        min_radius=0.03,
        max_radius=0.3,
        window_taper=0.4,
        peak_half_width=3,
        pad=1,
    )
    odometry = dataclasses.replace(odometry, feather=2)
    model = BevoPlus.create(odometry, BevGrid(0.1, (32, 32), near=3.0), n_angles=64, n_radii=16, reacquire_after=7)
    model = dataclasses.replace(model, map_feather=3)
    model = eqx.tree_at(lambda m: m.fix_log_std, model, jnp.array([-1.0, -2.0, -3.0], jnp.float32))
    checkpoint.save(tmp_path / "custom.ckpt", model)
    back, _, _ = checkpoint.load(tmp_path / "custom.ckpt")
    assert eqx.tree_equal(back, model)
    assert back.odometry.dpc.n_radii == 32 and back.odometry.dpc.pad == 1 and back.odometry.feather == 2
    assert back.map_feather == 3 and back.map_dpc.n_radii == 16 and back.reacquire_after == 7


def test_only_jbevo_classes_are_rebuilt(tmp_path):
    good = tmp_path / "good.ckpt"
    checkpoint.save(good, Bevo.create())
    with np.load(good) as data:
        arrays = dict(data)
    config = checkpoint.model_config(Bevo.create())
    config["model"]["module"] = "os:system"
    arrays["config"] = np.array(__import__("json").dumps(config))
    with open(tmp_path / "foreign.ckpt", "wb") as f:
        np.savez(f, **arrays)
    with pytest.raises(ValueError, match="only hold jbevo's classes"):
        checkpoint.load(tmp_path / "foreign.ckpt")


def test_a_checkpoint_without_a_field_added_since_takes_its_default(tmp_path):
    from jbevo.models.presets import street_model

    model = street_model(0.01)
    assert model.attitude.gap_rate_std > 0 and model.road_tilt is not None
    good = tmp_path / "street.ckpt"
    checkpoint.save(good, model)
    with np.load(good) as data:
        arrays = dict(data)

    def written(config, name):
        with open(tmp_path / name, "wb") as f:
            np.savez(f, **(arrays | {"config": np.array(__import__("json").dumps(config))}))
        return tmp_path / name

    # As written before the filter and the road tilt had these static fields: their defaults.
    config = checkpoint.model_config(model)
    fields = config["model"]["fields"]
    del fields["attitude"]["fields"]["gap_rate_std"], fields["road_tilt"]["fields"]["speed_coupling"]
    back, _, _ = checkpoint.load(written(config, "older.ckpt"))
    assert back.attitude.gap_rate_std == 0.0 and back.road_tilt.speed_coupling is True
    np.testing.assert_array_equal(back.attitude.motion_noise.log_std, model.attitude.motion_noise.log_std)
    # A field without a default, or one the class does not have, is still an error.
    config = checkpoint.model_config(model)
    del config["model"]["fields"]["attitude"]["fields"]["dt"]
    with pytest.raises(ValueError, match="SpeedAidedAttitude has the fields"):
        checkpoint.load(written(config, "no_dt.ckpt"))
    config = checkpoint.model_config(model)
    config["model"]["fields"]["attitude"]["fields"]["unknown"] = 1.0
    with pytest.raises(ValueError, match="SpeedAidedAttitude has the fields"):
        checkpoint.load(written(config, "unknown.ckpt"))
