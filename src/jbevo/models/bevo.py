"""BEVO: the pitch/roll DUKF, the gravity-aligned BEV and DPC composed into one differentiable
recursion over a sequence's frames (one ``lax.scan``; ``vmap`` over sequences).

Per frame ``t`` (:meth:`Bevo.step`):

1. **Attitude.** The speed-aided pitch/roll UKF (:class:`jbevo.inertial.speed_aided.SpeedAidedAttitude`:
   pitch, roll, gyro bias and forward speed) is predicted through the frame's gyro and
   accelerometer block; the speed integrates ``f_x + g sin(pitch)``.
2. **BEV.** The image is projected onto the ground with that pitch and roll
   (:func:`jbevo.vision.bev.bev_project`). Pixels outside the camera's view are filled with the mean
   of the valid ones and the view's edge is feathered (``feather`` pixels), so the edge, the same
   in every frame, does not pull the correlation toward zero motion.
3. **DPC.** :func:`jbevo.vision.registration.register` between the previous and the current BEV; the
   resulting forward speed and the accelerometer's lateral tilt update the attitude filter
   (the BEV of this frame used the prediction; the update serves the next frames).
4. **Metric motion.** :func:`jbevo.vision.bev.bev_increment` turns DPC's ``(rotation, t)`` into the
   body-frame increment ``(dx, dy, dyaw)`` (tested against ground truth). Poses compose with :func:`jbevo.geometry.se2.se2_compose`.

With ``bands`` (:mod:`jbevo.vision.bands`; for KITTI-size images), step 3 also registers the near and
far halves of the BEV pair: their forward-shift slope updates the filter's pitch and pitch-rate
bias before the odometry's speed does, the forward motion is extrapolated to where a pitch error
has no effect, the rotation is corrected by the bands' lateral shifts (a roll error's false
turn), and this frame's image is projected again with the updated attitude for the next frame.

Why speed-aided: the accelerometer's forward axis reads ``dv/dt - g sin(pitch)``, so its tilt is
off by ``dv/dt / g`` (2 m/s^2: 11.5 deg) whenever the car speeds up or brakes, and the BEV needs
pitch to a few hundredths of a degree (a pitch error ``d`` scales the BEV's apparent motion by
about ``1 - 2 d x / h``: 25 % per degree at x = 12 m, h = 1.65 m). Subtracting ``dv/dt``
differentiated from the odometry closes a loop (pitch error -> speed scale -> dv/dt -> pitch
measurement) with a gain of ~3.5 at 2 m/s^2, and diverged on every synthetic drive. Integrating
the forward accelerometer into a speed state that the odometry measures turns the same coupling
into negative feedback: an underestimated pitch makes the odometry's speed too high, which the
filter's speed-pitch correlation corrects toward the truth.

Output per frame (:class:`BevoOutput`): the increment from the previous frame (``(dx, dy, dyaw)``,
zero for frame 0), pitch, roll (the filter's prediction the BEV used), DPC confidence and the
planar pose. The learnable parameters are the attitude filter's Q (6) and R (2) (log standard
deviations) and DPC's six: 14, plus the bands' two (the slope's noise and the yaw gain); the
camera comes with each sequence (its calibration) and the BEV grid is static.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo.data.sequence import Sequence
from jbevo.filtering import ukf
from jbevo.geometry.se2 import se2_compose
from jbevo.inertial.kinematics import GRAVITY, accel_tilt, euler_rates, gyro_yaw_increment, tilt_measurements
from jbevo.inertial.speed_aided import SpeedAidedAttitude
from jbevo.models.parameters import num_learnable
from jbevo.vision.bands import BIAS_Y, BandGeometry
from jbevo.geometry.bev_grid import BevGrid
from jbevo.vision.bev import bev_increment, feathered_bev
from jbevo.geometry.camera import Camera
from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.registration import register


class BevoCarry(NamedTuple):
    """What the recursion carries from frame to frame."""

    attitude: ukf.GaussianState  #: the speed-aided attitude filter's belief
    bev: Float[Array, "h w"]  #: the previous frame's (feathered) BEV
    pose: Float[Array, " 3"]  #: the planar pose (x, y, yaw)


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
    ground truth, an upper bound). ``gyro_window`` (radians; 0: off) searches DPC's rotation
    only within that distance of the gyro's yaw increment over the frame
    (:func:`jbevo.registration.register`'s ``rotation_prior``): no gross rotation outliers on
    faint, noisy images (night), at the cost of trusting the gyro to that window. ``bands``
    (:class:`jbevo.bands.BandGeometry`, or None: off) refines each frame with the near and far
    halves of the BEV pair: a measurement of the pitch and the pitch-rate bias, the forward
    motion free of the pitch error, and the yaw free of the roll error.
    """

    attitude: SpeedAidedAttitude
    dpc: DPCParams
    grid: BevGrid = eqx.field(static=True)
    feather: int = eqx.field(static=True, default=4)
    attitude_source: str = eqx.field(static=True, default="filter")
    gyro_window: float = eqx.field(static=True, default=0.0)
    bands: BandGeometry | None = None

    @classmethod
    def create(
        cls, grid: BevGrid | None = None, imu_dt: float = 0.01, attitude_source: str = "filter",
        gyro_window: float = 0.0, bands: bool = False, **dpc_kwargs,
    ) -> Bevo:
        """Hand-set defaults: :meth:`SpeedAidedAttitude.create`, DPC's defaults with 256
        angles, and with ``bands`` :meth:`BandGeometry.create`."""
        if attitude_source not in ("filter", "zero", "accel", "truth"):
            raise ValueError(f"attitude_source must be filter, zero, accel or truth, got {attitude_source!r}")
        grid = BevGrid(0.1, (128, 128), near=7.5) if grid is None else grid
        dpc_kwargs.setdefault("n_angles", 256)
        return cls(
            SpeedAidedAttitude.create(imu_dt), DPCParams(**dpc_kwargs), grid, 4, attitude_source, float(gyro_window),
            BandGeometry.create() if bands else None,
        )

    def num_learnable(self) -> int:
        """Number of learnable scalars."""
        return num_learnable(self)

    def start(
        self, seq: Sequence, initial_pose: Float[Array, " 3"] | None = None, warm_start: bool = False
    ) -> tuple[BevoCarry, tuple, Sequence]:
        """The recursion's initial carry, the per-frame inputs to scan over and the sequence cast
        to the working dtype (float32, or float64 under ``jax_enable_x64``); see :meth:`__call__`."""
        if seq.images.ndim != 3:
            raise ValueError(f"Bevo runs on one sequence (images (T, H, W)); got images {seq.images.shape}: use jax.vmap")
        if initial_pose is None:
            initial_pose = jnp.nan_to_num(seq.planar[0])
        dtype = jnp.result_type(float)
        seq = eqx.tree_at(lambda q: (q.gyro, q.accel, q.poses), seq, (seq.gyro.astype(dtype), seq.accel.astype(dtype), seq.poses.astype(dtype)))
        # The state the first step starts from is the one before frame 0's IMU block (a frame
        # earlier): the first step integrates that block to reach frame 0.
        dt = self.frame_dt(seq)
        gyro0 = jnp.where(jnp.isfinite(seq.gyro[0]), seq.gyro[0], 0.0).mean(0)
        first = jnp.where(jnp.isfinite(seq.accel[0]), seq.accel[0], 0.0).mean(0)
        # Cold: the tilt of the block's mean force is the tilt half a block back; move it back
        # another half block.
        tilt_mid = accel_tilt(first)
        tilt0 = tilt_mid - 0.5 * dt * jnp.stack(euler_rates(tilt_mid[0], tilt_mid[1], gyro0))
        tilt0 = jnp.where(jnp.linalg.norm(first) > 0.5 * GRAVITY, tilt0, 0.0)
        speed0 = jnp.zeros((), dtype)
        if warm_start:
            # Frame 0's truth moved back through the block's mean rates; the speed is the forward
            # difference (its value half a frame on) moved back by one and a half frames of
            # acceleration.
            truth0 = seq.pitch_roll[0]
            tilt0 = truth0 - dt * jnp.stack(euler_rates(truth0[0], truth0[1], gyro0))
            accel_x = jnp.where(jnp.isfinite(seq.accel[0, :, 0]), seq.accel[0, :, 0], 0.0).mean()
            speed_dot = accel_x + GRAVITY * jnp.sin(truth0[0])
            speed0 = jnp.linalg.norm(seq.planar[1, :2] - seq.planar[0, :2]) / dt - 1.5 * dt * speed_dot
        mean = jnp.concatenate([tilt0, jnp.zeros(3, dtype), speed0[None]]).astype(dtype)
        # Cold: the first tilt is ~1.7 deg uncertain; warm: pitch and roll are known (0.1 deg).
        tilt_std = 0.002 if warm_start else 0.03
        cov = jnp.diag(jnp.asarray([tilt_std**2] * 2 + [0.005**2] * 3 + [0.1**2], dtype))
        carry = BevoCarry(ukf.GaussianState(mean, cov), jnp.zeros(self.grid.shape, dtype), jnp.asarray(initial_pose, dtype))
        frames = (seq.images, seq.gyro, seq.accel, seq.pitch_roll, jnp.arange(seq.images.shape[0]))
        return carry, frames, seq

    def frame_dt(self, seq: Sequence) -> float:
        """Seconds between frames: the IMU interval times the samples per frame."""
        return self.attitude.dt * seq.gyro.shape[-2]

    def step(
        self, carry: BevoCarry, frame: tuple, camera: Camera, frame_dt: float, reproject: bool = True
    ) -> tuple[BevoCarry, tuple]:
        """One frame of the recursion (module docstring): ``frame`` is one slice of the inputs
        :meth:`start` returns. Returns the new carry and ``(increment, pitch_roll, confidence,
        pose)``. With ``bands`` and the filter's attitude, the carried BEV is this frame's image
        projected again with the updated attitude (the next frame's pitch then differs from it by
        the gyro only); ``reproject=False`` leaves that to a caller that updates the attitude
        further (BEVO+)."""
        state, prev_bev, pose = carry
        image, gyro, accel, truth, index = frame
        dtype = prev_bev.dtype
        predicted = self.attitude.predict(state, gyro, accel)
        pitch_roll = {
            "filter": predicted.mean[:2].astype(dtype),
            "zero": jnp.zeros(2, dtype),
            "accel": jnp.nan_to_num(tilt_measurements(accel[None])[0]).astype(dtype),
            "truth": truth,
        }[self.attitude_source]
        bev = feathered_bev(image, pitch_roll[0], pitch_roll[1], camera, self.grid, self.feather)
        if self.gyro_window > 0:
            bias = predicted.mean[2:5].astype(dtype)
            turn = gyro_yaw_increment(gyro - bias, pitch_roll[0], pitch_roll[1], self.attitude.dt)
            reg = register(prev_bev, bev, self.dpc, rotation_prior=-turn, prior_window=self.gyro_window)
        else:
            reg = register(prev_bev, bev, self.dpc)
        rotation, translation = reg.rotation, reg.translation
        moving = index > 0
        filtered = self.attitude_source == "filter"
        if self.bands is not None:
            height = jnp.asarray(camera.height, dtype)
            shifts = self.bands.shifts(prev_bev, bev, reg, self.grid, self.dpc)
            measured = predicted
            if filtered:
                measured = self.bands.update_attitude(predicted, shifts, self.grid, self.dpc, height, frame_dt, moving)
            drift = (predicted.mean[BIAS_Y] - measured.mean[BIAS_Y]) * frame_dt
            rotation, translation = self.bands.motion(shifts, reg, self.grid, self.dpc, height, drift.astype(dtype))
            predicted = measured
        new_inc = jnp.where(moving, bev_increment(self.grid, rotation, translation), 0.0)
        speed = jnp.where(moving, new_inc[0] / frame_dt, jnp.nan)
        state = self.attitude.update(predicted, gyro, accel, speed)
        if self.bands is not None and filtered and reproject:
            bev = feathered_bev(image, state.mean[0].astype(dtype), state.mean[1].astype(dtype), camera, self.grid, self.feather)
        pose = se2_compose(pose, new_inc)
        confidence = jnp.where(moving, reg.confidence, 0.0)
        # The carry keeps its types (float32, or float64 under x64) whatever its parts compute in.
        new_carry = jax.tree_util.tree_map(lambda x, y: x.astype(y.dtype), BevoCarry(state, bev, pose), carry)
        return new_carry, (new_inc, pitch_roll, confidence, pose)

    def __call__(
        self, seq: Sequence, initial_pose: Float[Array, " 3"] | None = None, warm_start: bool = False
    ) -> BevoOutput:
        """Run over an unbatched sequence (``jax.vmap`` for batches). ``initial_pose`` defaults to
        the sequence's ground truth at frame 0 (zeros where unknown).

        Cold start (default): pitch and roll start at the tilt of the first accelerometer block
        and the speed at zero, right when a drive starts at rest. ``warm_start`` starts from the
        ground truth's pitch, roll and speed at frame 0 instead (moved back through frame 0's IMU
        block, which the first step integrates), as if the filter had run before: a window cut from the middle of a drive (training) may begin in a turn, where the
        uncompensated tilt is off by the centripetal acceleration (3 m/s^2: 18 degrees).
        """
        carry0, frames, seq = self.start(seq, initial_pose, warm_start)
        frame_dt = self.frame_dt(seq)

        @jax.checkpoint
        def step(carry, frame):
            return self.step(carry, frame, seq.camera, frame_dt)

        _, (increments, pitch_roll, confidence, poses) = jax.lax.scan(step, carry0, frames)
        return BevoOutput(increments, pitch_roll, confidence, poses)


__all__ = ["Bevo", "BevoCarry", "BevoOutput"]
