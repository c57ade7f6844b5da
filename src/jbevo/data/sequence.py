"""The :class:`Sequence` pytree: one recorded drive (camera images, IMU, calibration, ground
truth), its windows and batches.

Timing: frame ``t`` is taken at ``frame_times[t]``; the IMU block ``t`` holds the ``S`` samples
taken in ``[frame_times[t-1], frame_times[t])`` (block 0: the ``S`` samples before the first
frame), so a filter that integrates block ``t`` lands on frame ``t``. Every model steps over
frames with ``lax.scan``; windows of one length stack into a batched Sequence (leading axis on
every array, the camera included) that ``jax.vmap`` maps over.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, UInt8

from jbevo.geometry.camera import Camera


class Sequence(eqx.Module):
    """A drive of ``T`` frames with ``S`` IMU samples per frame (arrays may carry leading batch
    axes). Units: seconds, rad/s, m/s^2 (specific force), metres; body x forward, y left, z up.
    """

    images: UInt8[Array, "T H W"]  #: grayscale camera images, 8 bit as a camera gives them
    frame_times: Float[Array, " T"]
    imu_times: Float[Array, "T S"]
    gyro: Float[Array, "T S 3"]  #: body angular rate (NaN rows: missing samples)
    accel: Float[Array, "T S 3"]  #: body specific force (at rest and level: (0, 0, +g))
    camera: Camera
    poses: Float[Array, "T 4 4"]  #: ground truth T_world_body (camera centre), NaN where unknown

    @property
    def num_frames(self) -> int:
        return self.frame_times.shape[-1]

    @property
    def imu_dt(self) -> float:
        """Nominal IMU sample interval (seconds): the median frame step over ``S``, from the first
        batch element (the filters integrate ``S`` samples of ``imu_dt`` per frame, a block's
        missing rows filled with its mean; NaN for a single frame)."""
        t = np.asarray(self.frame_times, float).reshape(-1, self.frame_times.shape[-1])[0]
        if len(t) < 2:
            return float("nan")
        return float(np.median(np.diff(t))) / self.imu_times.shape[-1]

    @property
    def planar(self) -> Float[Array, "T 3"]:
        """Ground-truth planar pose ``(x, y, yaw)``."""
        r = self.poses[..., :3, :3]
        return jnp.stack([self.poses[..., 0, 3], self.poses[..., 1, 3], jnp.arctan2(r[..., 1, 0], r[..., 0, 0])], -1)

    @property
    def pitch_roll(self) -> Float[Array, "T 2"]:
        """Ground-truth ``(pitch, roll)`` (ZYX Euler)."""
        r = self.poses[..., :3, :3]
        pitch = -jnp.arcsin(jnp.clip(r[..., 2, 0], -1.0, 1.0))
        return jnp.stack([pitch, jnp.arctan2(r[..., 2, 1], r[..., 2, 2])], -1)


def check(seq: Sequence) -> Sequence:
    """Raise ``ValueError`` naming the field if the shapes disagree or times do not increase."""
    t = seq.frame_times.shape[-1]
    lead = seq.frame_times.shape[:-1]
    s = seq.imu_times.shape[-1]
    expected = {
        "images": (*lead, t, *seq.camera.image_shape),
        "imu_times": (*lead, t, s),
        "gyro": (*lead, t, s, 3),
        "accel": (*lead, t, s, 3),
        "poses": (*lead, t, 4, 4),
    }
    for name, shape in expected.items():
        got = tuple(getattr(seq, name).shape)
        if got != shape:
            raise ValueError(f"Sequence.{name} must have shape {shape}, got {got}")
    if t < 1 or s < 1:
        raise ValueError(f"a Sequence needs at least one frame and one IMU sample per frame, got T={t}, S={s}")
    frame_times = np.asarray(seq.frame_times)
    imu_times = np.asarray(seq.imu_times).reshape(*lead, -1)
    if not np.all(np.isfinite(frame_times)) or np.any(np.diff(frame_times, axis=-1) <= 0):
        raise ValueError("Sequence.frame_times must be finite and strictly increasing")
    if np.any(np.diff(imu_times, axis=-1) <= 0):
        raise ValueError("Sequence.imu_times must be strictly increasing")
    return seq


def window(seq: Sequence, start: int, length: int) -> Sequence:
    """Frames ``[start, start + length)`` of an unbatched sequence (with their IMU blocks)."""
    if not 0 <= start and start + length <= seq.num_frames and length >= 1:
        raise ValueError(f"window [{start}, {start + length}) is outside a sequence of {seq.num_frames} frames")
    sl = slice(start, start + length)
    return eqx.tree_at(
        lambda q: (q.images, q.frame_times, q.imu_times, q.gyro, q.accel, q.poses),
        seq,
        (seq.images[sl], seq.frame_times[sl], seq.imu_times[sl], seq.gyro[sl], seq.accel[sl], seq.poses[sl]),
    )


def check_stackable(seqs: list[Sequence]) -> None:
    """Raise ``ValueError`` unless ``seqs`` (at least one) share one length, IMU block size, camera
    image size and layout: what :func:`stack` needs."""
    if not seqs:
        raise ValueError("stack needs at least one sequence")
    structure = jax.tree_util.tree_structure(seqs[0])
    for i, q in enumerate(seqs[1:], 1):
        if jax.tree_util.tree_structure(q) != structure:
            raise ValueError(f"sequence {i} differs from sequence 0 in camera image size or layout")
        if q.frame_times.shape != seqs[0].frame_times.shape or q.imu_times.shape != seqs[0].imu_times.shape:
            raise ValueError(f"sequence {i} has {q.imu_times.shape} frames x IMU samples, sequence 0 {seqs[0].imu_times.shape}")


def stack(seqs: list[Sequence]) -> Sequence:
    """Batch sequences of one length and image size (a leading axis on every array)."""
    check_stackable(seqs)
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *seqs)


def windows(seq: Sequence, length: int, stride: int | None = None) -> Sequence:
    """All windows of ``length`` frames every ``stride`` (default ``length``) frames, batched."""
    stride = length if stride is None else stride
    if length < 1 or stride < 1 or length > seq.num_frames:
        raise ValueError(f"cannot cut windows of {length} frames (stride {stride}) from {seq.num_frames} frames")
    return stack([window(seq, s, length) for s in range(0, seq.num_frames - length + 1, stride)])


__all__ = ["Sequence", "check", "check_stackable", "stack", "window", "windows"]
