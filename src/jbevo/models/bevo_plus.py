"""BEVO+: map localization. BEVO's odometry predicts the planar pose, the frame's BEV is matched
by DPC against a crop of a map at that prediction, and a UKF over ``(x, y, yaw)`` fuses the two.

Per frame ``t`` (:meth:`BevoPlus.__call__`, one ``lax.scan``; ``vmap`` over sequences):

1. **Odometry.** :meth:`jbevo.models.bevo.Bevo.step`: the attitude filter, the BEV, DPC against the
   previous BEV, the body-frame increment ``u_t = (dx, dy, dyaw)``.
2. **Predict.** The pose filter composes ``u_t`` onto its state (:func:`planar_pose_model`) with
   the motion noise ``Q = diag(exp(2 motion_log_std))`` (per frame; learned).
3. **Map crop.** :func:`map_crop` resamples the map on the map-matching BEV grid at the predicted
   pose ``p`` (bilinear; the map has its own resolution and origin), with a mask of the pixels
   inside the map.
4. **Map matching.** The frame's BEV on the same grid (same pitch and roll as the odometry) and
   the crop are both limited to the pixels valid in both, feathered, and registered by DPC (their
   own learned :class:`jbevo.vision.dpc_params.DPCParams`): the crop is the view from ``p``, the BEV the
   view from the true pose, so :func:`jbevo.vision.bev.bev_increment` of their registration is the
   body-frame correction and ``p (+) correction`` the map fix ``z_t``.
5. **Update.** The fix updates the filter with the noise ``R(c)``: standard deviations
   ``exp(fix_log_std) * c ** -exp(log_confidence_power)`` along and across the body's heading and
   in yaw, where ``c`` is DPC's confidence times the fraction of the crop inside the map. A weak
   match barely moves the filter. A fix is *rejected* (the filter coasts on odometry) when ``c``
   is below ``min_confidence`` or when its normalised innovation squared exceeds ``gate`` (a
   chi-square bound for 3 degrees of freedom): a crop off the map, a textureless crop or a match
   on the wrong peak. :class:`LocalizationOutput` flags every rejected frame and carries the
   filter's position standard deviation, which grows while it coasts. Confident fixes that the
   gate rejects ``reacquire_after`` frames in a row mean the filter is the one that is wrong (a
   gross odometry failure): the fix is then taken with its innovation added to the covariance,
   and the output flags the re-anchoring.

6. **Pitch from the map.** The match also measures the BEV's pitch error (:func:`match_to_map`),
   which updates the attitude filter's pitch (noise ``exp(pitch_log_std)``, scaled by the
   confidence like ``R``): the BEV needs pitch to a few hundredths of a degree, and the map
   makes it observable.

Every learnable part (the odometry's 14, the map DPC's 6, ``motion_log_std`` 3,
``fix_log_std`` 3, ``log_confidence_power``, ``log_pitch_gain``, ``pitch_log_std``: 29 scalars) is trained end to end through
:func:`localization_loss` on the filtered positions and yaw.

The map's pixel ``(row, col)`` is world ``x = x_max - row * resolution``,
``y = y_max - col * resolution`` (:class:`jbevo.data.map.Map`): its axes are those of a BEV
at yaw 0.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jbevo.data.map import Map
from jbevo.data.sequence import Sequence
from jbevo.filtering import ukf
from jbevo.filtering.planar import CHI2_3DOF_999, YAW, planar_pose_model
from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import Camera
from jbevo.inertial.kinematics import gyro_yaw_increment
from jbevo.models.bevo import Bevo, BevoCarry, Frame, Observation
from jbevo.models.parameters import num_learnable
from jbevo.vision.bev import bev_project
from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.map_matching import MapMatch, match_to_map


class LocalizationCarry(NamedTuple):
    """What BEVO+'s recursion carries from frame to frame."""

    odometry: BevoCarry  #: BEVO's carry (attitude belief, previous BEV, dead-reckoned pose)
    pose: ukf.GaussianState  #: the pose filter's belief over (x, y, yaw)
    streak: Int[Array, ""]  #: confident map fixes rejected in a row


class LocalizationOutput(NamedTuple):
    """BEVO+'s output per frame (leading axis ``T``)."""

    poses: Float[Array, "T 3"]  #: filtered (x, y, yaw)
    covariances: Float[Array, "T 3 3"]  #: filtered covariance
    fixes: Float[Array, "T 3"]  #: the map fix of each frame (accepted or not)
    confidence: Float[Array, " T"]  #: map-match confidence (DPC times the map coverage)
    accepted: Bool[Array, " T"]  #: the fix updated the filter (False: coasting on odometry)
    reacquired: Bool[Array, " T"]  #: the filter was re-anchored on the map after repeated rejections
    position_std: Float[Array, " T"]  #: sqrt of the filtered position covariance's trace
    odometry: Float[Array, "T 3"]  #: BEVO's dead-reckoned poses (no map)
    increments: Float[Array, "T 3"]  #: BEVO's increments (dx, dy, dyaw)
    motion_covariances: Float[Array, "T 3 3"]  #: the Q of each frame's prediction (none at frame 0)


class BevoPlus(eqx.Module):
    """BEVO+: the ``odometry`` model, the map matcher's DPC parameters ``map_dpc``, the pose
    filter's per-frame motion noise and map-fix noise (module docstring), and the static
    map-matching grid, feathering, ``min_confidence`` and ``gate``."""

    odometry: Bevo
    map_dpc: DPCParams
    motion_log_std: Float[Array, " 3"]
    fix_log_std: Float[Array, " 3"]
    log_confidence_power: Float[Array, ""]
    log_pitch_gain: Float[Array, ""]
    pitch_log_std: Float[Array, ""]
    map_grid: BevGrid = eqx.field(static=True)
    map_feather: int = eqx.field(static=True, default=2)
    gyro_yaw: bool = eqx.field(static=True, default=True)
    min_confidence: float = eqx.field(static=True, default=0.05)
    gate: float = eqx.field(static=True, default=CHI2_3DOF_999)
    reacquire_after: int = eqx.field(static=True, default=5)

    @classmethod
    def create(
        cls,
        odometry: Bevo | None = None,
        map_grid: BevGrid | None = None,
        motion_std: tuple[float, float, float] = (0.02, 0.01, 0.001),
        fix_std: tuple[float, float, float] = (0.1, 0.1, 0.01),
        confidence_power: float = 1.0,
        pitch_gain: float = 1.33,
        pitch_std: float = 0.001,
        min_confidence: float = 0.05,
        gate: float = CHI2_3DOF_999,
        gyro_yaw: bool = True,
        reacquire_after: int = 5,
        **map_dpc_kwargs,
    ) -> BevoPlus:
        """Hand-set defaults: per-frame odometry noise 2 cm along, 1 cm across, 0.057 deg in yaw
        at full confidence (about twice that at a typical day-time confidence of 0.45);
        map fixes 10 cm and 0.57 deg at full confidence; the map's pitch measurement with gain
        1.33 (measured: the band model sees 0.75 of a pitch error) and 0.057 deg; a 64x64 map grid of 0.2 m from 4 m
        ahead; the map DPC with 128 angles."""
        odometry = Bevo.create() if odometry is None else odometry
        map_grid = BevGrid(0.2, (64, 64), near=4.0) if map_grid is None else map_grid
        map_dpc_kwargs.setdefault("n_angles", 128)
        f = jnp.float32
        return cls(
            odometry,
            DPCParams(**map_dpc_kwargs),
            jnp.log(jnp.asarray(motion_std, f)),
            jnp.log(jnp.asarray(fix_std, f)),
            jnp.log(f(confidence_power)),
            jnp.log(f(pitch_gain)),
            jnp.log(f(pitch_std)),
            map_grid,
            2,
            gyro_yaw,
            float(min_confidence),
            float(gate),
            int(reacquire_after),
        )

    def num_learnable(self) -> int:
        """Number of learnable scalars."""
        return num_learnable(self)

    def confidence_scale(self, confidence: Float[Array, ""]) -> Float[Array, ""]:
        """``c ** -exp(log_confidence_power)`` with ``c`` floored at ``min_confidence``: how much
        a noise standard deviation grows for a match of confidence ``c``."""
        return jnp.maximum(confidence, self.min_confidence) ** -jnp.exp(self.log_confidence_power)

    def motion_covariance(self, confidence: Float[Array, ""]) -> Float[Array, "3 3"]:
        """``Q(c)``: the per-frame odometry noise, ``exp(motion_log_std)`` scaled by the odometry
        DPC's confidence ``c`` to the power ``-exp(log_confidence_power)`` (a faint image, a weak
        odometry match: a looser motion model)."""
        return jnp.diag((jnp.exp(self.motion_log_std) * self.confidence_scale(confidence)) ** 2)

    def fix_covariance(self, yaw: Float[Array, ""], confidence: Float[Array, ""]) -> Float[Array, "3 3"]:
        """``R(c)``: the body-frame fix noise turned into the world frame at ``yaw``."""
        std = jnp.exp(self.fix_log_std) * self.confidence_scale(confidence)
        cy, sy = jnp.cos(yaw), jnp.sin(yaw)
        rot = jnp.eye(3, dtype=std.dtype).at[:2, :2].set(jnp.stack([jnp.stack([cy, -sy]), jnp.stack([sy, cy])]))
        return rot @ jnp.diag(std**2) @ rot.T

    def match(
        self, image: Array, pitch_roll: Float[Array, " 2"], camera: Camera, map_: Map, pose: Float[Array, " 3"]
    ) -> MapMatch:
        """Project an 8-bit ``image`` on the map-matching grid at ``pitch_roll`` and match it
        against the map at ``pose`` (:func:`match_to_map` with this model's parameters); with the
        odometry's ``road`` view, at the camera's attitude and height against the road."""
        road = self.odometry.road
        if road is not None:
            pitch_roll, camera = road.attitude(pitch_roll), road.camera(camera)
        bev, valid = bev_project(image.astype(pose.dtype) * (1.0 / 255.0), pitch_roll[0], pitch_roll[1], camera, self.map_grid)
        return match_to_map(
            bev, valid, map_, pose, self.map_grid, self.map_dpc, camera.height, jnp.exp(self.log_pitch_gain), self.map_feather
        )

    def __call__(
        self,
        seq: Sequence,
        map_: Map,
        initial_pose: Float[Array, " 3"] | None = None,
        initial_std: tuple[float, float, float] | Float[Array, " 3"] = (0.5, 0.5, 0.02),
        warm_start: bool = False,
    ) -> LocalizationOutput:
        """Localize an unbatched sequence on ``map_`` (``jax.vmap`` for batches). The filter
        starts at ``initial_pose`` (default: the ground truth at frame 0) with standard
        deviations ``initial_std``; ``warm_start`` as in :meth:`jbevo.models.bevo.Bevo.__call__`."""
        if map_.image.ndim != 2:
            raise ValueError(f"map image must be (rows, cols), got {map_.image.shape}: vmap over maps")
        odo = self.odometry
        carry0, frames, seq = odo.start(seq, initial_pose, warm_start)
        dtype = carry0.pose.dtype
        frame_dt = odo.frame_dt(seq)
        std0 = jnp.asarray(initial_std, dtype)
        pose0 = ukf.GaussianState(carry0.pose, jnp.diag(std0**2))

        @jax.checkpoint
        def step(carry: LocalizationCarry, frame: Frame):
            # 1. BEVO's odometry on this frame (its attitude belief after the IMU, bands, speed and
            #    lateral-tilt updates).
            seen = odo.observe(carry.odometry, frame, seq.camera, frame_dt)
            # 2. The pose filter predicts with the odometry's increment.
            predicted = self.predict_pose(carry.pose, seen, frame)
            # 3. The map fix, gated; 4. the pose update.
            match = self.match(frame.image, seen.pitch_roll, seq.camera, map_, predicted.mean)
            pose, accept, reacquire, streak = self.update_pose(predicted, match, carry.streak)
            # 5. The map's pitch measurement on the same attitude belief, then the odometry moves
            #    on with the BEV projected once more at that belief.
            pitch_std = jnp.exp(self.pitch_log_std) * self.confidence_scale(match.confidence)
            attitude = odo.attitude.update_pitch(seen.attitude, seen.pitch_roll[0] - match.pitch_error, pitch_std, accept)
            odometry = odo.advance(carry.odometry, seen, frame, seq.camera, attitude, reproject=True)
            pose = jax.tree_util.tree_map(lambda x, y: x.astype(y.dtype), pose, carry.pose)
            std = jnp.sqrt(jnp.maximum(pose.cov[0, 0] + pose.cov[1, 1], 0.0))
            out = LocalizationOutput(
                pose.mean,
                pose.cov,
                match.fix,
                match.confidence.astype(dtype),
                accept,
                reacquire,
                std,
                odometry.pose,
                self._increment(seen, frame),
                self._motion_cov(carry.pose, seen),
            )
            return LocalizationCarry(odometry, pose, streak), out

        _, outputs = jax.lax.scan(step, LocalizationCarry(carry0, pose0, jnp.zeros((), jnp.int32)), frames)
        return outputs

    def _increment(self, seen: Observation, frame: Frame) -> Float[Array, " 3"]:
        """The odometry's increment, its yaw from the gyro with ``gyro_yaw`` (per frame ~0.02 deg
        of bias against 0.3-0.8 deg for DPC's yaw; the map removes its drift)."""
        if not self.gyro_yaw:
            return seen.increment
        pitch_roll = seen.pitch_roll
        turn = gyro_yaw_increment(frame.gyro - seen.attitude.gyro_bias, pitch_roll[0], pitch_roll[1], self.odometry.attitude.dt)
        return seen.increment.at[YAW].set(jnp.where(frame.number > 0, turn, 0.0))

    def predict_pose(self, state: ukf.GaussianState, seen: Observation, frame: Frame) -> ukf.GaussianState:
        """The pose filter's prediction with the odometry's increment and ``Q(c)`` (none at
        frame 0)."""
        moved = ukf.predict(planar_pose_model(), state, self._increment(seen, frame), self._motion_cov(state, seen))
        return jax.tree_util.tree_map(lambda a, b: jnp.where(frame.number > 0, a, b), moved, state)

    def _motion_cov(self, state: ukf.GaussianState, seen: Observation) -> Float[Array, "3 3"]:
        return self.motion_covariance(seen.confidence).astype(state.mean.dtype)

    def update_pose(
        self, predicted: ukf.GaussianState, match: MapMatch, streak: Int[Array, ""]
    ) -> tuple[ukf.GaussianState, Bool[Array, ""], Bool[Array, ""], Int[Array, ""]]:
        """The pose filter's update with the map fix, gated (module docstring): ``(posterior,
        accepted, reacquired, the new streak of confident rejected fixes)``."""
        r = self.fix_covariance(match.fix[YAW], match.confidence).astype(predicted.mean.dtype)
        # Normalised innovation squared: the model's measurement is the state itself, so S = P + R.
        innovation = jnp.concatenate([match.fix[:2] - predicted.mean[:2], wrap_angle(match.fix[2:] - predicted.mean[2:])])
        nis = innovation @ jnp.linalg.solve(predicted.cov + r, innovation)
        usable = (match.confidence >= self.min_confidence) & jnp.all(jnp.isfinite(match.fix))
        # Confident fixes the gate keeps rejecting mean the filter, not the map, is wrong (a
        # gross odometry failure): after `reacquire_after` of them in a row, take the fix with
        # the innovation added to the covariance.
        disputed = usable & (match.confidence >= 2 * self.min_confidence) & (nis > self.gate)
        streak = jnp.where(disputed, streak + 1, 0)
        reacquire = jax.lax.stop_gradient(streak >= self.reacquire_after)
        streak = jnp.where(reacquire, 0, streak)
        inflated = predicted.cov + jnp.outer(innovation, innovation)
        predicted = predicted._replace(cov=jnp.where(reacquire, jax.lax.stop_gradient(inflated), predicted.cov))
        accept = jax.lax.stop_gradient(usable & ((nis <= self.gate) | reacquire))
        fix = jnp.where(accept, match.fix, predicted.mean)
        posterior, _ = ukf.update(planar_pose_model(), predicted, fix, r, mask=jnp.broadcast_to(accept, (3,)))
        return posterior, accept, reacquire, streak


__all__ = ["BevoPlus", "LocalizationCarry", "LocalizationOutput"]
