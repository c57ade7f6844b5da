import jax
import jax.numpy as jnp
import numpy as np

from jbevo import ukf
from jbevo.geometry import se2_between, se2_compose, wrap_angle
from jbevo.localization import planar_pose_model


def kitti_planar(path):
    """(x, y, yaw) in a z-up world from KITTI camera-0 poses (camera: x right, y down, z forward)."""
    poses = np.loadtxt(path).reshape(-1, 3, 4)
    x, y = poses[:, 2, 3], -poses[:, 0, 3]  # forward, left
    yaw = np.arctan2(-poses[:, 0, 2], poses[:, 2, 2])  # heading of the camera's z axis
    return jnp.asarray(np.stack([x, y, yaw], axis=-1))


def test_model_composes_increments_and_wraps_yaw():
    model = planar_pose_model()
    assert model is planar_pose_model()  # cached: one compilation for jitted callers
    out = model.motion(jnp.array([0.0, 0.0, np.pi - 0.1]), jnp.array([1.0, 0.0, 0.2]))
    np.testing.assert_allclose(out, [np.cos(np.pi - 0.1), np.sin(np.pi - 0.1), -np.pi + 0.1], atol=1e-12)


def test_fuses_real_kitti_motion_better_than_odometry_or_fixes_alone(reference_data):
    truth = kitti_planar(reference_data / "kitti_odom" / "gt_poses" / "09.txt")
    assert truth.shape == (1591, 3)
    true_inc = se2_between(truth[:-1], truth[1:])
    k_odo, k_fix, k_drop = jax.random.split(jax.random.PRNGKey(0), 3)
    odo_std, fix_std = jnp.array([0.05, 0.02, 0.002]), jnp.array([1.0, 1.0, 0.05])
    increments = true_inc + jax.random.normal(k_odo, true_inc.shape) * odo_std
    fixes = truth[1:] + jax.random.normal(k_fix, true_inc.shape) * fix_std
    fixes = fixes.at[:, 2].set(wrap_angle(fixes[:, 2]))
    fixes = jnp.where(jax.random.uniform(k_drop, (len(fixes), 1)) < 0.3, jnp.nan, fixes)

    res = ukf.filter(planar_pose_model(), ukf.GaussianState(truth[0], jnp.diag(fix_std**2)), increments, fixes,
                     jnp.diag(odo_std**2), jnp.diag(fix_std**2))
    filt_err = np.linalg.norm(np.asarray(res.filtered_mean[:, :2] - truth[1:, :2]), axis=1)
    fix_err = np.linalg.norm(np.asarray(fixes[:, :2] - truth[1:, :2]), axis=1)
    dead_reckoning = jax.lax.scan(lambda p, d: (se2_compose(p, d), se2_compose(p, d)), truth[0], increments)[1]
    odo_err = np.linalg.norm(np.asarray(dead_reckoning[:, :2] - truth[1:, :2]), axis=1)
    rmse = lambda e: float(np.sqrt(np.nanmean(e**2)))  # noqa: E731
    assert rmse(filt_err) < 0.6 * rmse(fix_err)
    assert rmse(filt_err) < 0.2 * rmse(odo_err)
    yaw_err = np.abs(np.asarray(wrap_angle(res.filtered_mean[:, 2] - truth[1:, 2])))
    assert np.degrees(yaw_err.mean()) < 1.0
