"""Baselines that BEVO+ is compared with: tracking by map matching alone (no odometry, no
filter)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jbevo.data.map import Map
from jbevo.data.sequence import Sequence
from jbevo.models.bevo_plus import BevoPlus


def map_matching_alone(model: BevoPlus, seq: Sequence, map_: Map) -> jax.Array:
    """Track by map matching only: each frame's crop at the previous frame's fix (the truth at
    frame 0), pitch and roll from BEVO's attitude filter (without the map's pitch); a fix below
    the confidence floor keeps the previous pose."""
    odo = model.odometry
    carry0, frames, seq = odo.start(seq, warm_start=True)
    frame_dt = odo.frame_dt(seq)

    def step(carry, frame):
        odo_carry, pose = carry
        odo_carry, row = odo.step(odo_carry, frame, seq.camera, frame_dt)
        match = model.match(frame.image, row.pitch_roll, seq.camera, map_, pose)
        ok = (match.confidence >= model.min_confidence) & jnp.all(jnp.isfinite(match.fix))
        pose = jnp.where(ok, match.fix, pose).astype(pose.dtype)
        return (odo_carry, pose), pose

    _, poses = jax.lax.scan(step, (carry0, carry0.pose), frames)
    return poses


__all__ = ["map_matching_alone"]
