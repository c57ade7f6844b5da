"""BEVO: the pitch/roll DUKF, the gravity-aligned BEV and DPC composed into one differentiable
recursion over a sequence's frames (one ``lax.scan``; ``vmap`` over sequences).

Per frame ``t`` (:meth:`Bevo.step`):

1. **Attitude.** The UKF state (pitch, roll, gyro bias) is predicted through the frame's gyro
   block and updated with the tilt of its accelerometer block, compensated for the centripetal
   acceleration ``w x v`` (``v``: the odometry's own speed over the last second, along body x).
   The longitudinal acceleration is *not* subtracted but inflates the measurement noise
   (adaptive R): a pitch error ``d`` scales the BEV's apparent motion by about ``1 - 2 d x / h``
   (x ~ 12 m ahead, camera height h: 25 % per degree), so ``dv/dt`` from the odometry feeds a
   pitch error back into the pitch measurement with a gain of ~3.5 at 2 m/s^2: that loop
   diverged on every synthetic drive. Down-weighting the tilt while the car speeds up or brakes
   cannot diverge; the gyro (and its bias state) carries the attitude through.
2. **BEV.** The image is projected onto the ground with that pitch and roll
   (:func:`jbevo.camera.bev_project`). Pixels outside the camera's view are filled with the mean
   of the valid ones and the view's edge is feathered (``feather`` pixels), so the edge, the same
   in every frame, does not pull the correlation toward zero motion.
3. **DPC.** :func:`jbevo.registration.register` between the previous and the current BEV.
4. **Metric motion.** With ``R = R(dyaw)`` (standard, counter-clockwise), BEV origin ``o`` and
   image centre ``c`` (both ``(col, row)``), and ``S`` the swap of the two axes, DPC's
   ``(rotation, t)`` gives ``dyaw = -rotation`` and the body-frame increment
   ``(dx, dy) = resolution * R S (t - (R - I)(c - o))`` (derivation in the README's BEVO
   section; tested against ground truth). Poses compose with :func:`jbevo.geometry.se2_compose`.

Output per frame (:class:`BevoOutput`): the increment from the previous frame (``(dx, dy, dyaw)``,
zero for frame 0), pitch, roll, DPC confidence and the planar pose. The learnable parameters
are the attitude filter's Q and R (log standard deviations) and DPC's six; the camera comes with
each sequence (its calibration) and the BEV grid is static.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo import ukf
from jbevo.attitude import GRAVITY, AttitudeFilter, accel_tilt, attitude_model
from jbevo.camera import BevGrid, bev_project
from jbevo.datasets.sequence import Sequence
from jbevo.geometry import se2_between, se2_compose, wrap_angle
from jbevo.registration import DPCParams, register


MAX_COMPENSATION = 5.0  # m/s^2
VELOCITY_WINDOW = 10  # frames of odometry behind the speed and acceleration estimates


class BevoOutput(NamedTuple):
    increments: Float[Array, "T 3"]  #: (dx, dy, dyaw) from frame t-1 to t, body frame of t-1
    pitch_roll: Float[Array, "T 2"]
    confidence: Float[Array, " T"]  #: DPC confidence (0 for frame 0)
    poses: Float[Array, "T 3"]  #: (x, y, yaw), from the initial pose


class Bevo(eqx.Module):
    """The BEVO odometry model: learnable ``attitude`` (Q, R) and ``dpc`` parameters, a static
    BEV ``grid``. ``feather`` (pixels) softens the edge of the camera's view in the BEV;
    ``attitude_source`` picks the pitch/roll that project the BEV: ``"filter"`` (BEVO),
    ``"zero"`` (no IMU), ``"accel"`` (the raw accelerometer tilt) or ``"truth"`` (the sequence's
    ground truth, an upper bound).
    """

    attitude: AttitudeFilter
    dpc: DPCParams
    grid: BevGrid = eqx.field(static=True)
    feather: int = eqx.field(static=True, default=4)
    attitude_source: str = eqx.field(static=True, default="filter")

    @classmethod
    def create(
        cls, grid: BevGrid | None = None, imu_dt: float = 0.01, attitude_source: str = "filter", **dpc_kwargs
    ) -> Bevo:
        """Hand-set defaults: the attitude filter with a gyro-bias state
        (:meth:`AttitudeFilter.create`) and DPC's defaults with 256 angles."""
        if attitude_source not in ("filter", "zero", "accel", "truth"):
            raise ValueError(f"attitude_source must be filter, zero, accel or truth, got {attitude_source!r}")
        grid = BevGrid(0.1, (128, 128), near=7.5) if grid is None else grid
        dpc_kwargs.setdefault("n_angles", 256)
        return cls(
            AttitudeFilter.create(imu_dt, gyro_bias=True), DPCParams(**dpc_kwargs), grid, 4, attitude_source
        )

    def num_learnable(self) -> int:
        """Number of learnable scalars."""
        leaves = jax.tree_util.tree_leaves(eqx.filter(self, eqx.is_inexact_array))
        return sum(int(x.size) for x in leaves)

    # ------------------------------------------------------------------ pieces of a step
    def _attitude_step(self, state: ukf.GaussianState, gyro, accel, speed, accel_long):
        """One frame of the pitch/roll UKF. The tilt measurement is compensated for the
        centripetal acceleration ``w x v`` (``v = (speed, 0, 0)``: a car does not slip sideways)
        and its noise is inflated by the false tilt an uncompensated longitudinal acceleration
        ``accel_long`` (m/s^2) would cause."""
        f = self.attitude
        ok = jnp.all(jnp.isfinite(gyro), axis=-1, keepdims=True)
        count = jnp.maximum(jnp.sum(ok), 1)
        mean_gyro = jnp.sum(jnp.where(ok, gyro, 0.0), axis=0) / count
        gyro = jnp.where(ok, jnp.where(ok, gyro, 0.0), mean_gyro)
        model = attitude_model(f.dt, f.gyro_bias)
        predicted = ukf.predict(model, state, gyro, f.motion_noise())
        v3 = jnp.stack([speed, jnp.zeros_like(speed), jnp.zeros_like(speed)])
        compensation = jnp.cross(mean_gyro, v3)
        # A gross registration error must not tilt the attitude: a car's acceleration stays
        # below ~1 g, so larger predictions are scaled down to MAX_COMPENSATION.
        norm = jnp.sqrt(jnp.sum(compensation**2) + 1e-12)
        compensation = compensation * jnp.minimum(1.0, MAX_COMPENSATION / norm)
        a_ok = jnp.all(jnp.isfinite(accel), axis=-1, keepdims=True)
        a_count = jnp.sum(a_ok)
        mean_accel = jnp.sum(jnp.where(a_ok, accel, 0.0), axis=0) / jnp.maximum(a_count, 1)
        z = jnp.where(a_count > 0, accel_tilt(mean_accel - compensation), jnp.nan)
        r = f.measurement_noise()
        # Speed errors of the odometry (a degree of pitch error scales the BEV's motion by ~30 %)
        # make the centripetal term uncertain too: 30 % of it.
        false_tilt = jnp.stack([accel_long, 0.3 * jnp.sqrt(compensation[1] ** 2 + 1e-12)]) / GRAVITY
        # Robust (Cauchy-like) weighting: a tilt far from the prediction is mostly acceleration
        # the compensation missed (starting, braking), seen at once, without the lag of an
        # acceleration estimate; its weight falls as the square of the innovation.
        innovation = jnp.where(jnp.isfinite(z), z - predicted.mean[:2], 0.0)
        r = r + jnp.diag(false_tilt**2 + innovation**2)
        if f.gyro_bias:
            state, _ = ukf.update(model, predicted, z, r, measurement_input=v3)
        else:
            state, _ = ukf.update(model, predicted, z, r)
        return state, z

    def _bev(self, image, pitch, roll, camera) -> Array:
        bev, valid = bev_project(image.astype(pitch.dtype) * (1.0 / 255.0), pitch, roll, camera, self.grid)
        weight = _feathered(valid.astype(bev.dtype), self.feather)
        mean = jnp.sum(bev * valid) / jnp.maximum(jnp.sum(valid), 1.0)
        return mean + weight * (bev - mean)

    def _increment(self, rotation, translation) -> Float[Array, " 3"]:
        dyaw = -rotation
        c, s = jnp.cos(dyaw), jnp.sin(dyaw)
        r = jnp.array([[c, -s], [s, c]])
        rows, cols = self.grid.shape
        centre = jnp.array([(cols - 1) / 2, (rows - 1) / 2], translation.dtype)
        origin = jnp.array([self.grid.origin[1], self.grid.origin[0]], translation.dtype)
        t = translation - (r - jnp.eye(2)) @ (centre - origin)
        d = self.grid.resolution * r @ t[::-1]  # S swaps (x, y) = (col, row)
        return jnp.stack([d[0], d[1], wrap_angle(dyaw)])

    # ------------------------------------------------------------------ the recursion
    def __call__(
        self, seq: Sequence, initial_pose: Float[Array, " 3"] | None = None, warm_start: bool = False
    ) -> BevoOutput:
        """Run over an unbatched sequence (``jax.vmap`` for batches). ``initial_pose`` defaults to
        the sequence's ground truth at frame 0 (zeros where unknown).

        Cold start (default): pitch and roll start at the tilt of the first accelerometer block
        and the speed at zero, right when a drive starts at rest. ``warm_start`` starts from the
        ground truth's pitch, roll and speed at frame 0 instead, as if the filter had run
        before: a window cut from the middle of a drive (training) may begin in a turn, where the
        uncompensated tilt is off by the centripetal acceleration (3 m/s^2: 18 degrees).
        """
        if seq.images.ndim != 3:
            raise ValueError(f"Bevo runs on one sequence (images (T, H, W)); got images {seq.images.shape}: use jax.vmap")
        if initial_pose is None:
            initial_pose = jnp.nan_to_num(seq.planar[0])
        dtype = jnp.result_type(float)  # float32, or float64 under jax_enable_x64
        seq = eqx.tree_at(lambda q: (q.gyro, q.accel, q.poses), seq, (seq.gyro.astype(dtype), seq.accel.astype(dtype), seq.poses.astype(dtype)))
        s = seq.gyro.shape[1]
        frame_dt = self.attitude.dt * s
        n = 5 if self.attitude.gyro_bias else 2
        first = jnp.where(jnp.isfinite(seq.accel[0]), seq.accel[0], 0.0).mean(0)
        tilt0 = jnp.where(jnp.linalg.norm(first) > 0.5 * GRAVITY, accel_tilt(first), 0.0)
        if warm_start:
            tilt0 = seq.pitch_roll[0]
        mean = jnp.concatenate([tilt0, jnp.zeros(n - 2, tilt0.dtype)]).astype(dtype)
        cov = jnp.diag(jnp.asarray([0.03**2] * 2 + [0.005**2] * (n - 2), dtype))
        h, w = self.grid.shape
        k = VELOCITY_WINDOW
        # The last second of increments: at rest before a cold start; the true speed held for a
        # second before a warm start.
        step0 = jnp.linalg.norm(seq.planar[1, :2] - seq.planar[0, :2]) if warm_start else 0.0
        history = jnp.zeros((k, 2), dtype).at[:, 0].set(step0)
        carry0 = (ukf.GaussianState(mean, cov), jnp.zeros((h, w), dtype), history, initial_pose.astype(dtype))

        @jax.checkpoint
        def step(carry, frame):
            state, prev_bev, past, pose = carry
            image, gyro, accel, truth, index = frame
            # Speed and longitudinal acceleration from the last second of odometry: a single
            # frame's increment is too noisy to differentiate (camera-height bounce alone moves
            # the BEV by centimetres); sums over half a second are not.
            half = k // 2
            v_new = jnp.sum(past[half:, 0]) / (half * frame_dt)
            v_old = jnp.sum(past[:half, 0]) / (half * frame_dt)
            speed = 0.5 * (v_new + v_old)
            accel_long = jnp.sqrt(((v_new - v_old) / (half * frame_dt)) ** 2 + 1e-6)
            state, z = self._attitude_step(state, gyro, accel, speed, accel_long)
            pitch_roll = {
                "filter": state.mean[:2].astype(dtype),
                "zero": jnp.zeros(2, state.mean.dtype),
                "accel": jnp.nan_to_num(z),
                "truth": truth,
            }[self.attitude_source]
            bev = self._bev(image, pitch_roll[0], pitch_roll[1], seq.camera)
            reg = register(prev_bev, bev, self.dpc)
            new_inc = jnp.where(index > 0, self._increment(reg.rotation, reg.translation), 0.0)
            pose = se2_compose(pose, new_inc)
            confidence = jnp.where(index > 0, reg.confidence, 0.0)
            past = jnp.concatenate([past[1:], new_inc[None, :2]])
            # The carry keeps its types (float32, or float64 under x64) whatever its parts compute in.
            new_carry = jax.tree_util.tree_map(lambda x, y: x.astype(y.dtype), (state, bev, past, pose), carry)
            return new_carry, (new_inc, pitch_roll, confidence, pose)

        frames = (seq.images, seq.gyro, seq.accel, seq.pitch_roll, jnp.arange(seq.images.shape[0]))
        _, (increments, pitch_roll, confidence, poses) = jax.lax.scan(step, carry0, frames)
        return BevoOutput(increments, pitch_roll, confidence, poses)


def _feathered(valid: Float[Array, "H W"], width: int) -> Float[Array, "H W"]:
    """The valid mask eroded and smoothed by a ``width``-pixel box filter applied twice (a
    triangle ramp from 0 at the view's edge to 1 ``width`` pixels inside)."""
    if width <= 0:
        return valid
    k = jnp.ones(2 * width + 1, valid.dtype) / (2 * width + 1)
    eroded = 1.0 - jnp.clip(_box(1.0 - valid, k) * (2 * width + 1), 0.0, 1.0)
    return _box(eroded, k)


def _box(image, k):
    image = jax.vmap(lambda r: jnp.convolve(r, k, mode="same"))(image)
    return jax.vmap(lambda c: jnp.convolve(c, k, mode="same"), in_axes=1, out_axes=1)(image)


def relative_motion(seq: Sequence) -> Float[Array, "T 3"]:
    """Ground-truth increments ``(dx, dy, dyaw)`` from frame t-1 to t (zero for frame 0)."""
    planar = seq.planar
    inc = se2_between(planar[:-1], planar[1:])
    return jnp.concatenate([jnp.zeros_like(inc[:1]), inc])


def motion_loss(
    output: BevoOutput, seq: Sequence, yaw_weight: float = 10.0, huber: float = 0.3, trajectory_weight: float = 0.0
) -> Float[Array, ""]:
    """Mean Huber loss of the per-frame motion error ``e = |d(x, y)|^2 + (yaw_weight * d yaw)^2``
    (metres; ``yaw_weight`` in metres per radian: at 10, a 0.1 deg yaw error weighs as 1.7 cm):
    ``e / 2`` below ``huber^2`` and linear in ``sqrt(e)`` above, so that a few gross registration
    failures do not drown the gradient of the many good frames. Plus ``trajectory_weight`` times
    the mean squared position error of the accumulated poses."""
    truth = relative_motion(seq)
    err = output.increments - truth
    sq_err = err[1:, 0] ** 2 + err[1:, 1] ** 2 + (yaw_weight * wrap_angle(err[1:, 2])) ** 2
    norm = jnp.sqrt(sq_err + 1e-12)
    per_frame = jnp.where(norm <= huber, 0.5 * sq_err, huber * (norm - 0.5 * huber))
    loss = jnp.mean(per_frame)
    if trajectory_weight:
        loss = loss + trajectory_weight * jnp.mean(jnp.sum((output.poses[:, :2] - seq.planar[:, :2]) ** 2, -1))
    return loss


__all__ = ["Bevo", "BevoOutput", "motion_loss", "relative_motion"]
