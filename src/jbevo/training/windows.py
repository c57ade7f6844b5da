"""Training windows cut from whole drives."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jbevo.data import sequence as sq


def training_windows(seqs: list[sq.Sequence], window: int, stride: int | None = None) -> sq.Sequence:
    """Every window of ``window`` frames every ``stride`` frames (default: half a window) of the
    sequences long enough for one, batched along a leading axis. ``ValueError`` if none is.
    ``window`` 0 batches the whole sequences (which must then share one length)."""
    if window == 0:
        return sq.stack(seqs)
    stride = max(1, window // 2) if stride is None else stride
    parts = [sq.windows(s, window, stride) for s in seqs if s.num_frames >= window]
    if not parts:
        raise ValueError(f"no sequence has {window} frames for a window; lower the window")
    return jax.tree_util.tree_map(lambda *x: jnp.concatenate(x), *parts)


__all__ = ["training_windows"]
