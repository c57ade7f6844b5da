"""BEVO: the pitch/roll DUKF, the gravity-aligned BEV and DPC composed into one differentiable
recursion over a sequence's frames (one ``lax.scan``; ``vmap`` over sequences).

Per frame ``t`` (:meth:`Bevo.step`: :meth:`Bevo.observe`, then :meth:`Bevo.advance`), on one
attitude belief (:class:`jbevo.inertial.speed_aided.AttitudeState`):

1. **Attitude.** The speed-aided pitch/roll UKF (:class:`jbevo.inertial.speed_aided.SpeedAidedAttitude`:
   pitch, roll, gyro bias and forward speed) is predicted through the frame's gyro and
   accelerometer block; the speed integrates ``f_x + g sin(pitch)``.
2. **BEV.** The image is projected onto the ground with that pitch and roll
   (:func:`jbevo.vision.bev.bev_project`). Pixels outside the camera's view are filled with the mean
   of the valid ones and the view's edge is feathered (``feather`` pixels), so the edge, the same
   in every frame, does not pull the correlation toward zero motion.
3. **DPC.** :func:`jbevo.vision.registration.register` between the previous and the current BEV; the
   resulting forward speed, then the accelerometer's lateral tilt, update the attitude belief
   (the BEV of this frame used the prediction; the updates serve the next frames).
4. **Metric motion.** :func:`jbevo.vision.bev.bev_increment` turns DPC's ``(rotation, t)`` into the
   body-frame increment ``(dx, dy, dyaw)`` (tested against ground truth). Poses compose with :func:`jbevo.geometry.se2.se2_compose`.

With ``bands`` (:mod:`jbevo.vision.bands`; for KITTI-size images), step 3 also registers the near and
far halves of the BEV pair: their forward-shift slope updates the filter's pitch and pitch-rate
bias before the odometry's speed does, the forward motion is extrapolated to where a pitch error
has no effect, the rotation is corrected by the bands' lateral shifts (a roll error's false
turn), and this frame's image is projected again with the updated attitude for the next frame.
With keyframes (:attr:`jbevo.vision.bands.BandGeometry.keyframes`), the band pair is this BEV and
the last one at which the bands engaged, and they engage once the travel since reaches their gate:
a slow car measures the slope over several frames. The filter's pitch corrections since that BEV
are taken out of the pair's slope (:meth:`jbevo.vision.bands.BandGeometry.remove_drift`).

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

For real streets (:func:`jbevo.models.presets.street_model`), three optional parts: the road
view (:mod:`jbevo.vision.road_view`: the camera's pitch, roll and height against the road, and a
road corridor that fades parked cars and facades; 4 learnable), the yaw fusion
(:mod:`jbevo.models.yaw_fusion`: DPC's turn averaged with the gyro's; 1) and the road tilt
(:mod:`jbevo.models.road_tilt`: with bands, the slope measures the road's grade, a state of its
own added to the projection's pitch, instead of correcting the pitch against gravity, and the
odometry's speed measures it together with the filter's speed; 1).
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, UInt8

from jbevo.data.sequence import Sequence
from jbevo.filtering.ukf import GaussianState
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import Camera
from jbevo.geometry.se2 import se2_compose
from jbevo.inertial.kinematics import (
    GRAVITY,
    accel_tilt,
    euler_rates,
    forward_acceleration,
    gyro_yaw_increment,
    tilt_measurements,
    valid_mean,
)
from jbevo.inertial.speed_aided import AttitudeState, SpeedAidedAttitude
from jbevo.models.forward_fusion import BIAS_STD, COLD_SPEED_STD, WARM_SPEED_STD, ForwardFusion
from jbevo.models.parameters import num_learnable
from jbevo.models.road_tilt import RoadTilt
from jbevo.models.yaw_fusion import YawFusion
from jbevo.vision.bands import BandGeometry
from jbevo.vision.bev import bev_increment, feathered_bev
from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.registration import Registration, register
from jbevo.vision.road_view import RoadView

ATTITUDE_SOURCES = ("filter", "zero", "accel", "truth")


class Frame(NamedTuple):
    """One frame of a sequence as the recursion scans it (leading axis ``T`` when batched)."""

    image: UInt8[Array, "H W"]  #: the camera image, 8 bit
    gyro: Float[Array, "S 3"]  #: the IMU block that ends at this frame (rad/s; NaN rows: missing)
    accel: Float[Array, "S 3"]  #: its specific force (m/s^2)
    true_pitch_roll: Float[Array, " 2"]  #: the ground truth's (used by ``attitude_source="truth"`` only)
    number: Int[Array, ""]  #: the frame's index in the sequence (0: no previous BEV)


class Keyframe(NamedTuple):
    """The BEV the bands compare with when they hold keyframes
    (:attr:`jbevo.vision.bands.BandGeometry.keyframes`; an empty BEV without)."""

    bev: Float[Array, "h w"]  #: the keyframe's BEV, as the carry kept it
    turn: Float[Array, ""]  #: the gyro's turn from the keyframe to the previous frame (radians)
    age: Int[Array, ""]  #: frames from the keyframe to the previous frame (0: it is the previous frame)
    #: the pitch corrections the filter made after the keyframe's BEV was projected (radians): the
    #: estimate's change that the gyro did not make, which the band pair would read as a slope
    pitch_drift: Float[Array, ""]


class BevoCarry(NamedTuple):
    """What the recursion carries from frame to frame."""

    attitude: AttitudeState  #: the speed-aided attitude filter's belief
    bev: Float[Array, "h w"]  #: the previous frame's (feathered) BEV
    pose: Float[Array, " 3"]  #: the planar pose (x, y, yaw)
    road_tilt: GaussianState  #: the road's tilt along the heading (level and unused without ``road_tilt``)
    keyframe: Keyframe  #: the bands' keyframe (unused without keyframes)
    forward: GaussianState  #: the forward speed, travel and acceleration bias (unused without ``forward``)


class Observation(NamedTuple):
    """What one frame's odometry measured (:meth:`Bevo.observe`)."""

    attitude: AttitudeState  #: the belief after the frame's measurement updates
    road_tilt: GaussianState  #: the road's tilt after the frame's update
    pitch_roll: Float[Array, " 2"]  #: the body's attitude the frame's BEV was projected with
    bev: Float[Array, "h w"]  #: that BEV
    increment: Float[Array, " 3"]  #: (dx, dy, dyaw) from the previous frame (body frame; 0 at frame 0)
    confidence: Float[Array, ""]  #: DPC's confidence (0 at frame 0)
    gyro_turn: Float[Array, ""]  #: the gyro's yaw increment over the frame (radians)
    keyframe: Bool[Array, ""]  #: this frame becomes the bands' keyframe (with keyframes)
    forward: GaussianState  #: the forward speed, travel and acceleration bias after the frame's update (with ``forward``)


class BevoOutput(NamedTuple):
    """BEVO's output per frame (leading axis ``T``)."""

    increments: Float[Array, "T 3"]  #: (dx, dy, dyaw) from frame t-1 to t, body frame of t-1
    #: the attitude source's pitch and roll at each frame's BEV (the filter's prediction: against
    #: gravity), before the road view's camera offsets and the road tilt
    pitch_roll: Float[Array, "T 2"]
    confidence: Float[Array, " T"]  #: DPC confidence (0 for frame 0)
    poses: Float[Array, "T 3"]  #: (x, y, yaw), from the initial pose
    #: the road tilt state's mean that the frame's BEV was projected with (radians; 0 without one)
    road_tilt: Float[Array, " T"]
    #: the pitch and roll each BEV was projected with, before the road view's camera offsets:
    #: ``pitch_roll`` with ``road_tilt`` added to the pitch, or on a level road
    #: (:attr:`jbevo.models.road_tilt.RoadTilt.level`) ``(road_tilt, 0)``
    projection: Float[Array, "T 2"]


class Bevo(eqx.Module):
    """The BEVO odometry model: learnable ``attitude`` (Q, R) and ``dpc`` parameters, a static
    BEV ``grid``.

    Attributes:
        attitude: the speed-aided attitude filter's noise (:class:`SpeedAidedAttitude`).
        dpc: DPC's parameters.
        grid: the BEV raster (static).
        feather: pixels over which the edge of the camera's view in the BEV fades to its mean.
        attitude_source: the pitch/roll that project the BEV: ``"filter"`` (BEVO), ``"zero"``
            (no IMU), ``"accel"`` (the raw accelerometer tilt) or ``"truth"`` (the sequence's ground
            truth, an upper bound).
        gyro_window: radians (0: off); DPC's rotation is searched only within that distance of
            the gyro's yaw increment over the frame (:func:`jbevo.vision.registration.register`'s
            ``rotation_prior``): no gross rotation outliers on faint, noisy images (night), at the
            cost of trusting the gyro to that window.
        bands: :class:`jbevo.vision.bands.BandGeometry`, or None (off): the near and far halves
            of the BEV pair measure the pitch and the pitch-rate bias, give the forward motion free
            of the pitch error and the yaw free of the roll error.
        road: :class:`jbevo.vision.road_view.RoadView`, or None (off): the camera's pitch, roll
            and height against the road on top of the body's attitude and the nominal height,
            and the road corridor that fades the BEV's columns beside the lane (real streets).
        yaw_fusion: :class:`jbevo.models.yaw_fusion.YawFusion`, or None (off): the turn is DPC's
            rotation averaged with the gyro's yaw increment by inverse variance.
        road_tilt: :class:`jbevo.models.road_tilt.RoadTilt`, or None (off): with bands and the
            filter's attitude, the bands' slope updates the road's tilt (added to the pitch the
            BEV is projected with, or on a level road the pitch itself) instead of the filter's
            pitch against gravity, and the odometry's speed updates the tilt and the filter's
            speed together (:meth:`jbevo.models.road_tilt.RoadTilt.update_with_speed`).
        forward: :class:`jbevo.models.forward_fusion.ForwardFusion`, or None (off): the forward
            motion per frame from the accelerometer's speed and DPC's increment together (the
            attitude filter still takes DPC's own).

    Example::

        >>> from jbevo.data.synthetic import procedural_sequence
        >>> seq = procedural_sequence(seed=0, frames=20)                 # doctest: +SKIP
        >>> out = Bevo.create()(seq)                                     # doctest: +SKIP
        >>> out.poses.shape                                              # doctest: +SKIP
        (20, 3)
    """

    attitude: SpeedAidedAttitude
    dpc: DPCParams
    grid: BevGrid = eqx.field(static=True)
    feather: int = eqx.field(static=True, default=4)
    attitude_source: str = eqx.field(static=True, default="filter")
    gyro_window: float = eqx.field(static=True, default=0.0)
    bands: BandGeometry | None = None
    road: RoadView | None = None
    yaw_fusion: YawFusion | None = None
    road_tilt: RoadTilt | None = None
    forward: ForwardFusion | None = None

    @classmethod
    def create(
        cls,
        grid: BevGrid | None = None,
        imu_dt: float = 0.01,
        attitude_source: str = "filter",
        gyro_window: float = 0.0,
        bands: bool = False,
        road: bool = False,
        yaw_fusion: bool = False,
        road_tilt: bool = False,
        forward_fusion: bool = False,
        **dpc_kwargs,
    ) -> Bevo:
        """Hand-set defaults: :meth:`SpeedAidedAttitude.create`, DPC's defaults with 256
        angles, a 128 x 128 BEV at 0.1 m from 7.5 m ahead, with ``bands``
        :meth:`BandGeometry.create`, with ``road`` :meth:`RoadView.create`, with ``yaw_fusion``
        :meth:`YawFusion.create`, with ``road_tilt`` :meth:`RoadTilt.create` and with
        ``forward_fusion`` :meth:`ForwardFusion.create`."""
        if attitude_source not in ATTITUDE_SOURCES:
            raise ValueError(f"attitude_source must be one of {ATTITUDE_SOURCES}, got {attitude_source!r}")
        grid = BevGrid(0.1, (128, 128), near=7.5) if grid is None else grid
        dpc_kwargs.setdefault("n_angles", 256)
        return cls(
            SpeedAidedAttitude.create(imu_dt),
            DPCParams(**dpc_kwargs),
            grid,
            4,
            attitude_source,
            float(gyro_window),
            BandGeometry.create() if bands else None,
            RoadView.create() if road else None,
            YawFusion.create() if yaw_fusion else None,
            RoadTilt.create() if road_tilt else None,
            ForwardFusion.create() if forward_fusion else None,
        )

    def num_learnable(self) -> int:
        """Number of learnable scalars."""
        return num_learnable(self)

    def frame_dt(self, seq: Sequence) -> float:
        """Seconds between frames: the IMU interval times the samples per frame."""
        return self.attitude.dt * seq.gyro.shape[-2]

    # ------------------------------------------------------------------ the recursion's start

    def start(
        self, seq: Sequence, initial_pose: Float[Array, " 3"] | None = None, warm_start: bool = False
    ) -> tuple[BevoCarry, Frame, Sequence]:
        """The recursion's initial carry, the frames to scan over and the sequence cast to the
        working dtype (float32, or float64 under ``jax_enable_x64``); see :meth:`__call__`."""
        if seq.images.ndim != 3:
            raise ValueError(f"Bevo runs on one sequence (images (T, H, W)); got images {seq.images.shape}: use jax.vmap")
        if initial_pose is None:
            initial_pose = jnp.nan_to_num(seq.planar[0])
        dtype = jnp.result_type(float)
        seq = eqx.tree_at(
            lambda q: (q.gyro, q.accel, q.poses), seq, (seq.gyro.astype(dtype), seq.accel.astype(dtype), seq.poses.astype(dtype))
        )
        attitude = self.initial_attitude(seq, warm_start).astype(dtype)
        tilt = (self.road_tilt or RoadTilt.create()).initial(dtype)
        zero = jnp.zeros((), dtype)
        keyframe = Keyframe(
            jnp.zeros(self.grid.shape if self._keyframes else (0, 0), dtype), zero, jnp.zeros((), jnp.int32), zero
        )
        bias_std = BIAS_STD if self.forward is None else self.forward.bias_std
        forward = ForwardFusion.initial(attitude.speed, WARM_SPEED_STD if warm_start else COLD_SPEED_STD, dtype, bias_std)
        carry = BevoCarry(attitude, jnp.zeros(self.grid.shape, dtype), jnp.asarray(initial_pose, dtype), tilt, keyframe, forward)
        frames = Frame(seq.images, seq.gyro, seq.accel, seq.pitch_roll, jnp.arange(seq.images.shape[0]))
        return carry, frames, seq

    def initial_attitude(self, seq: Sequence, warm_start: bool = False) -> AttitudeState:
        """The attitude belief before frame 0's IMU block (the first step integrates that block
        to reach frame 0). Cold: the tilt of the block's mean specific force, moved back half a
        block through the mean gyro (that tilt is the one half a block back), the speed zero
        (right when a drive starts at rest), pitch and roll ~1.7 deg uncertain. Warm: the
        truth's pitch and roll moved back through the block, the speed from the first two true
        positions moved back by one and a half frames of acceleration, 0.1 deg uncertain."""
        dt = self.frame_dt(seq)
        gyro0, _, _ = valid_mean(seq.gyro[0])
        force0, _, _ = valid_mean(seq.accel[0])
        if warm_start:
            truth0 = seq.pitch_roll[0]
            tilt0 = truth0 - dt * jnp.stack(euler_rates(truth0[0], truth0[1], gyro0))
            speed_dot = forward_acceleration(force0[0], truth0[0])
            speed0 = jnp.linalg.norm(seq.planar[1, :2] - seq.planar[0, :2]) / dt - 1.5 * dt * speed_dot
            return AttitudeState.initial(tilt0, speed0, 0.002, 0.005, 0.1)
        tilt_mid = accel_tilt(force0)
        tilt0 = tilt_mid - 0.5 * dt * jnp.stack(euler_rates(tilt_mid[0], tilt_mid[1], gyro0))
        tilt0 = jnp.where(jnp.linalg.norm(force0) > 0.5 * GRAVITY, tilt0, 0.0)
        return AttitudeState.initial(tilt0, jnp.zeros((), tilt0.dtype), 0.03, 0.005, 0.1)

    # ------------------------------------------------------------------ one frame

    def projection_attitude(self, belief: AttitudeState, frame: Frame) -> Float[Array, " 2"]:
        """The attitude source's pitch and roll for this frame's BEV (before any road tilt)."""
        dtype = belief.mean.dtype
        if self.attitude_source == "filter":
            return belief.pitch_roll
        if self.attitude_source == "zero":
            return jnp.zeros(2, dtype)
        if self.attitude_source == "accel":
            return jnp.nan_to_num(tilt_measurements(frame.accel[None])[0]).astype(dtype)
        return frame.true_pitch_roll.astype(dtype)

    def bev(self, image: UInt8[Array, "H W"], pitch_roll: Float[Array, " 2"], camera: Camera) -> Float[Array, "h w"]:
        """The feathered BEV of an 8-bit image at the body's ``pitch_roll``
        (:func:`jbevo.vision.bev.feathered_bev`); with ``road``, at the camera's attitude and
        height against the road and with the columns outside the road corridor faded."""
        if self.road is None:
            return feathered_bev(image, pitch_roll[0], pitch_roll[1], camera, self.grid, self.feather)
        pitch, roll = self.road.attitude(pitch_roll)
        bev = feathered_bev(image, pitch, roll, self.road.camera(camera), self.grid, self.feather)
        return self.road.keep_road(bev, self.grid)

    def camera_height(self, camera: Camera, dtype) -> Float[Array, ""]:
        """The camera's height above the road the BEV assumes (metres)."""
        return jnp.asarray(camera.height if self.road is None else self.road.height(camera), dtype)

    @property
    def _level_road(self) -> bool:
        """Whether the BEV is projected on the road's plane whatever the filter's attitude."""
        return self.road_tilt is not None and self.road_tilt.level

    @property
    def _keyframes(self) -> bool:
        return self.bands is not None and self.bands.keyframes

    def _register(self, prev: Array, bev: Array, gyro_turn: Array) -> Registration:
        if self.gyro_window > 0:
            return register(prev, bev, self.dpc, rotation_prior=-gyro_turn, prior_window=self.gyro_window)
        return register(prev, bev, self.dpc)

    def observe(self, carry: BevoCarry, frame: Frame, camera: Camera, frame_dt: float) -> Observation:
        """One frame's odometry, top to bottom, on one attitude belief: the IMU prediction (and
        the road tilt's walk), the BEV at the predicted attitude, DPC against the previous BEV,
        then the measurement updates (the bands' pitch and pitch-rate bias, or the road's tilt,
        from the bands engaged at this frame's travel, or with keyframes at the travel since the
        keyframe; the odometry's speed; the lateral tilt)."""
        # A missing gyro block widens the attitude from frame 1 on (frame 0's block precedes the
        # first image; the initial belief states its uncertainty) and only where the filter sets
        # the attitude (the other sources also run on sequences without any IMU).
        widen = (frame.number > 0) if self.attitude_source == "filter" else False
        belief = self.attitude.predict(carry.attitude, frame.gyro, frame.accel, widen)
        pitch_roll = self.projection_attitude(belief, frame)
        tilt = carry.road_tilt
        if self.road_tilt is not None:
            tilt = self.road_tilt.predict(tilt, belief.speed * frame_dt)
        bev = self.bev(frame.image, self._on_road(pitch_roll, tilt), camera)
        gyro_turn = gyro_yaw_increment(frame.gyro - belief.gyro_bias, pitch_roll[0], pitch_roll[1], self.attitude.dt)
        reg = self._register(carry.bev, bev, gyro_turn)
        moving = frame.number > 0
        rotation, translation = reg.rotation, reg.translation
        keyframe = ~moving
        if self.bands is not None:
            height = self.camera_height(camera, bev.dtype)
            # The band pair: the previous BEV, or with keyframes the keyframe's (the previous
            # BEV when it is the keyframe, age 0).
            earlier, pair, key_dt, consecutive = carry.bev, reg, frame_dt, jnp.bool_(True)
            if self._keyframes:
                key = carry.keyframe
                earlier = key.bev
                pair = self._register(earlier, bev, key.turn.astype(gyro_turn.dtype) + gyro_turn)
                key_dt, consecutive = frame_dt * (key.age + 1).astype(bev.dtype), key.age == 0
            shifts = self.bands.shifts(earlier, bev, pair, self.grid, self.dpc)
            engaged = moving
            if self.bands.min_travel > 0:
                engaged = moving & (bev_increment(self.grid, pair.rotation, pair.translation)[0] >= self.bands.min_travel)
            keyframe = keyframe | engaged
            measured = belief
            if self.attitude_source == "filter":
                # The keyframe's pitch relative to this BEV's that the filter's corrections since
                # the keyframe account for (zero for the previous BEV, projected again after them).
                known = -carry.keyframe.pitch_drift.astype(bev.dtype)
                slope_shifts = self.bands.remove_drift(shifts, self.grid, self.dpc, height, known) if self._keyframes else shifts
                slope = self.bands.slope_measurement(slope_shifts, self.grid, self.dpc, height, key_dt)
                if self.road_tilt is None:
                    h = AttitudeState.row(pitch=slope.pitch, pitch_rate_bias=slope.pitch_rate_bias, dtype=belief.mean.dtype)
                    measured = self.attitude.update_linear(belief, h, slope.value, slope.variance, engaged & slope.valid)
                else:
                    tilt = self.road_tilt.update(tilt, slope, engaged & slope.valid)
            # The previous BEV's pitch relative to this one's, as the update estimates it.
            drift = ((belief.pitch_rate_bias - measured.pitch_rate_bias) * frame_dt).astype(bev.dtype)
            banded = self.bands.motion(shifts, pair, self.grid, self.dpc, height, drift)
            # A keyframe's pair spans several frames: the frame's own motion is then the full
            # registration's between consecutive BEVs.
            rotation = jnp.where(engaged & consecutive, banded[0], rotation)
            translation = jnp.where(engaged & consecutive, banded[1], translation)
            belief = measured
        if self.yaw_fusion is not None:
            rotation = self.yaw_fusion.fuse(rotation, gyro_turn.astype(rotation.dtype))
        increment = jnp.where(moving, bev_increment(self.grid, rotation, translation), 0.0)
        dpc_forward = increment[0]  # the attitude filter's speed measurement, with or without fusion
        forward = carry.forward
        if self.forward is not None:
            # The forward speed through the IMU block at the body's pitch against gravity, then
            # DPC's forward increment; the posterior travel is the frame's forward motion.
            forward = self.forward.predict(forward, frame.accel, belief.pitch.astype(forward.mean.dtype), self.attitude.dt)
            forward = self.forward.update(forward, dpc_forward, moving)
            increment = increment.at[0].set(jnp.where(moving, ForwardFusion.travel(forward).astype(increment.dtype), 0.0))
        speed = jnp.where(moving, dpc_forward / frame_dt, jnp.nan)
        if self.road_tilt is None:
            belief = self.attitude.update_speed(belief, speed)
        else:
            sensitivity = 2.0 * self.grid.centre_distance / self.camera_height(camera, bev.dtype)
            sensitivity = sensitivity if self.road_tilt.speed_coupling else jnp.zeros_like(sensitivity)
            belief, tilt = self.road_tilt.update_with_speed(self.attitude, belief, tilt, speed, sensitivity)
        belief = self.attitude.update_lateral_tilt(belief, frame.gyro, frame.accel)
        confidence = jnp.where(moving, reg.confidence, 0.0)
        return Observation(belief, tilt, pitch_roll, bev, increment, confidence, gyro_turn.astype(bev.dtype), keyframe, forward)

    def _on_road(self, pitch_roll: Float[Array, " 2"], tilt: GaussianState) -> Float[Array, " 2"]:
        """The attitude a BEV is projected with: the body's ``pitch_roll``, with ``road_tilt`` its
        pitch plus the road's tilt, or on a level road the tilt and no roll."""
        if self.road_tilt is None:
            return pitch_roll
        pitch = tilt.mean[0].astype(pitch_roll.dtype)
        if self.road_tilt.level:
            return jnp.stack([pitch, jnp.zeros_like(pitch)])
        return pitch_roll.at[0].add(pitch)

    def advance(
        self,
        carry: BevoCarry,
        observation: Observation,
        frame: Frame,
        camera: Camera,
        attitude: AttitudeState | None = None,
        reproject: bool | None = None,
    ) -> BevoCarry:
        """The carry for the next frame: the final ``attitude`` (default: the observation's),
        this frame's BEV, projected once more at that attitude when ``reproject`` (default: with
        bands; BEVO+ re-projects after the map's pitch) and the filter sets the attitude (so the
        next BEV pair differs by the gyro only), the pose moved by the increment, and with
        keyframes the keyframe: this frame where the bands engaged (or at frame 0), else the
        old one with this frame's turn and pitch corrections added."""
        attitude = observation.attitude if attitude is None else attitude
        reproject = self.bands is not None if reproject is None else reproject
        bev = observation.bev
        reproject = reproject and self.attitude_source == "filter"
        if reproject:
            bev = self.bev(frame.image, self._on_road(attitude.pitch_roll.astype(bev.dtype), observation.road_tilt), camera)
        keyframe = carry.keyframe
        if self._keyframes:
            # The filter's corrections to its pitch (the road's tilt changes only at a keyframe)
            # accumulate until the next keyframe, whose BEV, projected again, has them.
            reset = observation.keyframe
            correction = jnp.zeros((), bev.dtype)
            if self.attitude_source == "filter" and not self._level_road:
                correction = (attitude.pitch_roll[0] - observation.pitch_roll[0]).astype(bev.dtype)
                correction = jnp.where(reset & reproject, 0.0, correction)
            keyframe = Keyframe(
                jnp.where(reset, bev, keyframe.bev),
                jnp.where(reset, 0.0, keyframe.turn + observation.gyro_turn),
                jnp.where(reset, 0, keyframe.age + 1),
                jnp.where(reset, 0.0, keyframe.pitch_drift) + correction,
            )
        new = BevoCarry(
            attitude, bev, se2_compose(carry.pose, observation.increment), observation.road_tilt, keyframe, observation.forward
        )
        # The carry keeps its types (float32, or float64 under x64) whatever its parts compute in.
        return jax.tree_util.tree_map(lambda x, y: x.astype(y.dtype), new, carry)

    def step(self, carry: BevoCarry, frame: Frame, camera: Camera, frame_dt: float) -> tuple[BevoCarry, BevoOutput]:
        """One frame of the recursion: :meth:`observe`, then :meth:`advance`. Returns the new
        carry and this frame's row of :class:`BevoOutput`."""
        observation = self.observe(carry, frame, camera, frame_dt)
        # The frame's BEV is projected with the tilt's prediction, whose mean is the carry's.
        tilt = carry.road_tilt.mean[0] if self.road_tilt is not None else jnp.zeros((), carry.road_tilt.mean.dtype)
        projection = self._on_road(observation.pitch_roll, carry.road_tilt)
        carry = self.advance(carry, observation, frame, camera)
        return carry, BevoOutput(
            observation.increment, observation.pitch_roll, observation.confidence, carry.pose, tilt, projection
        )

    def __call__(self, seq: Sequence, initial_pose: Float[Array, " 3"] | None = None, warm_start: bool = False) -> BevoOutput:
        """Run over an unbatched sequence (``jax.vmap`` for batches). ``initial_pose`` defaults to
        the sequence's ground truth at frame 0 (zeros where unknown).

        Cold start (default): pitch and roll start at the tilt of the first accelerometer block
        and the speed at zero, right when a drive starts at rest. ``warm_start`` starts from the
        ground truth's pitch, roll and speed at frame 0 instead (:meth:`initial_attitude`), as
        if the filter had run before: a window cut from the middle of a drive (training) may
        begin in a turn, where the uncompensated tilt is off by the centripetal acceleration
        (3 m/s^2: 18 degrees).
        """
        carry0, frames, seq = self.start(seq, initial_pose, warm_start)
        frame_dt = self.frame_dt(seq)

        @jax.checkpoint
        def step(carry, frame):
            return self.step(carry, frame, seq.camera, frame_dt)

        _, outputs = jax.lax.scan(step, carry0, frames)
        return outputs


__all__ = ["ATTITUDE_SOURCES", "Bevo", "BevoCarry", "BevoOutput", "Frame", "Keyframe", "Observation"]
