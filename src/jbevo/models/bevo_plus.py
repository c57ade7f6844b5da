"""BEVO+: map localization. BEVO's odometry predicts the planar pose, the frame's BEV is matched
by DPC against a crop of a map at that prediction, and a UKF over ``(x, y, yaw)`` fuses the two.

Per frame ``t`` (:meth:`BevoPlus.__call__`, one ``lax.scan``; ``vmap`` over sequences):

1. **Odometry.** :meth:`jbevo.odometry.Bevo.step`: the attitude filter, the BEV, DPC against the
   previous BEV, the body-frame increment ``u_t = (dx, dy, dyaw)``.
2. **Predict.** The pose filter composes ``u_t`` onto its state (:func:`planar_pose_model`) with
   the motion noise ``Q = diag(exp(2 motion_log_std))`` (per frame; learned).
3. **Map crop.** :func:`map_crop` resamples the map on the map-matching BEV grid at the predicted
   pose ``p`` (bilinear; the map has its own resolution and origin), with a mask of the pixels
   inside the map.
4. **Map matching.** The frame's BEV on the same grid (same pitch and roll as the odometry) and
   the crop are both limited to the pixels valid in both, feathered, and registered by DPC (their
   own learned :class:`jbevo.registration.DPCParams`): the crop is the view from ``p``, the BEV the
   view from the true pose, so :func:`jbevo.camera.bev_increment` of their registration is the
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
``y = y_max - col * resolution`` (:class:`jbevo.datasets.maps.Map`): its axes are those of a BEV
at yaw 0.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from jbevo.data.map import Map
from jbevo.data.sequence import Sequence
from jbevo.filtering import ukf
from jbevo.filtering.planar import CHI2_3DOF_999, YAW, planar_pose_model
from jbevo.geometry.angles import wrap_angle
from jbevo.inertial.kinematics import gyro_yaw_increment
from jbevo.models.bevo import Bevo
from jbevo.models.parameters import num_learnable
from jbevo.geometry.bev_grid import BevGrid
from jbevo.vision.bev import bev_project, feathered_bev
from jbevo.geometry.camera import Camera
from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.map_matching import MapMatch, match_to_map


class LocalizationOutput(NamedTuple):
    poses: Float[Array, "T 3"]  #: filtered (x, y, yaw)
    covariances: Float[Array, "T 3 3"]  #: filtered covariance
    fixes: Float[Array, "T 3"]  #: the map fix of each frame (accepted or not)
    confidence: Float[Array, " T"]  #: map-match confidence (DPC times the map coverage)
    accepted: Bool[Array, " T"]  #: the fix updated the filter (False: coasting on odometry)
    reacquired: Bool[Array, " T"]  #: the filter was re-anchored on the map after repeated rejections
    position_std: Float[Array, " T"]  #: sqrt of the filtered position covariance's trace
    odometry: Float[Array, "T 3"]  #: BEVO's dead-reckoned poses (no map)
    increments: Float[Array, "T 3"]  #: BEVO's increments (dx, dy, dyaw)


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
            odometry, DPCParams(**map_dpc_kwargs), jnp.log(jnp.asarray(motion_std, f)), jnp.log(jnp.asarray(fix_std, f)),
            jnp.log(f(confidence_power)), jnp.log(f(pitch_gain)), jnp.log(f(pitch_std)), map_grid, 2, gyro_yaw, float(min_confidence), float(gate), int(reacquire_after),
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

    def match(self, image: Array, pitch_roll: Float[Array, " 2"], camera: Camera, map_: Map, pose: Float[Array, " 3"]) -> MapMatch:
        """Project an 8-bit ``image`` on the map-matching grid at ``pitch_roll`` and match it
        against the map at ``pose`` (:func:`match_to_map` with this model's parameters)."""
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
        deviations ``initial_std``; ``warm_start`` as in :meth:`jbevo.odometry.Bevo.__call__`."""
        if map_.image.ndim != 2:
            raise ValueError(f"map image must be (rows, cols), got {map_.image.shape}: vmap over maps")
        odo = self.odometry
        carry0, frames, seq = odo.start(seq, initial_pose, warm_start)
        dtype = carry0.pose.dtype
        frame_dt = odo.frame_dt(seq)
        model = planar_pose_model()
        std0 = jnp.asarray(initial_std, dtype)
        state0 = ukf.GaussianState(carry0.pose, jnp.diag(std0**2))
        zero = jnp.zeros((), dtype)

        @jax.checkpoint
        def step(carry, frame):
            odo_carry, state, streak = carry
            image, index = frame[0], frame[-1]
            odo_carry, (inc, pitch_roll, odo_conf, odo_pose) = odo.step(odo_carry, frame, seq.camera, frame_dt, reproject=False)
            q = self.motion_covariance(odo_conf).astype(dtype)
            if self.gyro_yaw:
                bias = odo_carry.attitude.mean[2:5]
                turn = gyro_yaw_increment(frame[1] - bias, pitch_roll[0], pitch_roll[1], odo.attitude.dt)
                inc = inc.at[2].set(jnp.where(index > 0, turn, 0.0))
            moved = ukf.predict(model, state, inc, q)
            predicted = jax.tree_util.tree_map(lambda a, b: jnp.where(index > 0, a, b), moved, state)
            match = self.match(image, pitch_roll, seq.camera, map_, predicted.mean)
            r = self.fix_covariance(match.fix[YAW], match.confidence).astype(dtype)
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
            filtered, _ = ukf.update(model, predicted, fix, r, mask=jnp.broadcast_to(accept, (3,)))
            filtered = jax.tree_util.tree_map(lambda x, y: x.astype(y.dtype), filtered, state)
            # The map measures the pitch the BEV was projected with minus the true one: a linear
            # measurement of the attitude filter's pitch, which sets the BEV of the next frames.
            pitch_std = jnp.exp(self.pitch_log_std) * self.confidence_scale(match.confidence)
            attitude = _measure_pitch(odo_carry.attitude, pitch_roll[0] - match.pitch_error, pitch_std, accept)
            odo_carry = odo_carry._replace(attitude=jax.tree_util.tree_map(lambda x, y: x.astype(y.dtype), attitude, odo_carry.attitude))
            if odo.attitude_source == "filter":
                # The next odometry match compares this frame's BEV with the next one: project it
                # again with the corrected pitch (with bands: the updated attitude), or a
                # correction would look like a jump.
                if odo.bands is None:
                    pitch, roll = jnp.where(accept, attitude.mean[0], pitch_roll[0]), pitch_roll[1]
                else:
                    pitch, roll = attitude.mean[0], attitude.mean[1]
                odo_bev = feathered_bev(image, pitch.astype(dtype), roll.astype(dtype), seq.camera, odo.grid, odo.feather)
                odo_carry = odo_carry._replace(bev=odo_bev.astype(odo_carry.bev.dtype))
            std = jnp.sqrt(jnp.maximum(filtered.cov[0, 0] + filtered.cov[1, 1], zero))
            out = (filtered.mean, filtered.cov, match.fix, match.confidence.astype(dtype), accept, reacquire, std, odo_pose, inc)
            return (odo_carry, filtered, streak), out

        _, outputs = jax.lax.scan(step, (carry0, state0, jnp.zeros((), jnp.int32)), frames)
        return LocalizationOutput(*outputs)


def _measure_pitch(state: ukf.GaussianState, pitch: Array, std: Array, accept: Array) -> ukf.GaussianState:
    """Kalman update of the attitude belief (pitch first) with a direct pitch measurement; the
    belief unchanged where ``accept`` is False."""
    h = jnp.zeros_like(state.mean).at[0].set(1.0)
    return ukf.linear_update(state, h, pitch - state.mean[0], std**2, accept)


__all__ = ["BevoPlus", "LocalizationOutput"]
