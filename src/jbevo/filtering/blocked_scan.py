"""``lax.scan`` in blocks whose buffers stay small, for the filters' few-number steps on XLA:CPU.

XLA:CPU runs the body of a loop as a sequence of kernels ("thunks"). It runs them one after the
other only when every buffer they touch is at most 512 bytes (or the body has at most 8 kernels);
otherwise it schedules them as a dependency graph, which costs an allocation and queue work on
every iteration. A plain ``lax.scan`` body always touches the whole stacked inputs and outputs
(``(T, ...)`` arrays), so a filter step of a 3-state model, a few dozen small kernels, is run as
a graph on every step.

:func:`blocked_scan` runs the same recursion as two nested scans: the outer one over blocks of
``K`` steps, the inner one over the steps of a block, whose stacked inputs and outputs are
``(K, ...)`` arrays. ``K`` is chosen so that every per-block slice of the stacked inputs and
outputs (and the carry) fits in 512 bytes; the inner body, where the work is, then runs in order
if the step's own intermediates are that small too (``block_size`` does not see them: a step
with larger ones gains nothing and pays the nesting). Each step runs the same operations as
``lax.scan``'s step, on the same values in the same order; the tests and ``benchmarks/ukf.py``
find the per-step results equal bit for bit (a sum over all steps taken afterwards may round
differently). ``benchmarks/ukf.py`` times it on the 3-state localization UKF (docs/filtering.md
has the table): the forward filters and the filter + RTS
smoother of one sequence run faster; under ``vmap`` the batch makes every buffer large anyway and
the blocks only add work, and so do gradients, whose stored residuals are large (and which take
longer to compile). The filters therefore take ``block=1`` (one ``lax.scan``) by default and
``"auto"`` on request.

Either way, :func:`blocked_scan` compiles its loops as one XLA:CPU kernel where the step allows
(:func:`jbevo.filtering.cpu_kernel.one_kernel`; ``one_kernel=False`` keeps plain loops): no
kernels are called per step at all, which removes the cost the blocks work around and is faster
than them (docs/filtering.md).
"""

from __future__ import annotations

from collections.abc import Callable
from math import prod
from typing import Any, Literal, TypeVar

import jax
import jax.numpy as jnp

from jbevo.filtering import cpu_kernel

Carry = TypeVar("Carry")

#: XLA:CPU runs a loop body's kernels in order when every buffer they use is at most this many
#: bytes (``ThunkExecutor::Options::execute_sequential_buffer_threshold``, not configurable).
SEQUENTIAL_BUFFER_BYTES = 512


def _step_bytes(leaf: Any) -> int:
    """Bytes of one step's slice of a stacked leaf (shape ``(T, ...)``)."""
    return prod(leaf.shape[1:]) * jnp.dtype(leaf.dtype).itemsize


def _bytes(leaf: Any) -> int:
    return prod(jnp.shape(leaf)) * jnp.dtype(leaf.dtype).itemsize


def block_size(f: Callable, init: Any, xs: Any, length: int) -> int:
    """The block length ``block="auto"`` gives :func:`blocked_scan` for ``f`` over ``xs``.

    ``K_max`` is the most steps whose stacked inputs and outputs fit in
    :data:`SEQUENTIAL_BUFFER_BYTES` per leaf. The block is the largest divisor of ``length`` up to
    ``K_max`` (no left-over steps, so the step is compiled once); if that is 1, ``K_max`` itself
    (the left-over steps run as a second, separately compiled scan). 1 (a plain scan) where
    ``K_max < 2``, a carry leaf alone exceeds the threshold, or the backend is not the CPU.
    """
    if jax.default_backend() != "cpu" or length < 2:
        return 1
    if max((_bytes(leaf) for leaf in jax.tree.leaves(init)), default=0) > SEQUENTIAL_BUFFER_BYTES:
        return 1
    x0 = jax.tree.map(lambda a: jax.ShapeDtypeStruct(a.shape[1:], a.dtype), xs)
    _, y0 = jax.eval_shape(f, init, x0)  # traces the step only where the carry fits
    widest = max([_step_bytes(leaf) for leaf in jax.tree.leaves(xs)] + [_bytes(leaf) for leaf in jax.tree.leaves(y0)])
    most = min(SEQUENTIAL_BUFFER_BYTES // max(widest, 1), length)
    if most < 2:
        return 1
    divisor = max(k for k in range(1, most + 1) if length % k == 0)
    return divisor if divisor >= 2 else most


def blocked_scan(
    f: Callable[[Carry, Any], tuple[Carry, Any]],
    init: Carry,
    xs: Any,
    *,
    block: int | Literal["auto"] = "auto",
    reverse: bool = False,
    unroll: int = 1,
    one_kernel: bool = True,
) -> tuple[Carry, Any]:
    """``jax.lax.scan(f, init, xs, reverse=reverse, unroll=unroll)``, run as blocks of ``block``
    steps (``"auto"``: :func:`block_size`; 1 is a plain scan). Steps that do not fill a last
    block run as a plain scan after the blocks (before them in reverse). ``unroll`` applies to
    the scans over steps. ``xs`` must have at least one leaf (the filters always scan over
    inputs). With ``one_kernel`` the loops are compiled as one XLA:CPU kernel where the step
    allows (:func:`jbevo.filtering.cpu_kernel.one_kernel`): the same results to round-off."""
    leaves = jax.tree.leaves(xs)
    if not leaves:
        raise ValueError("blocked_scan needs inputs xs with a leading axis")
    length = leaves[0].shape[0]
    if block == "auto":
        block = block_size(f, init, xs, length)
    if not isinstance(block, int) or isinstance(block, bool) or block < 1:
        raise ValueError(f'block must be a positive int or "auto", got {block!r}')
    block = min(block, max(length, 1))
    if not one_kernel:
        return _scan_in_blocks(f, init, xs, block, reverse, unroll)
    return cpu_kernel.one_kernel(lambda c, x: _scan_in_blocks(f, c, x, block, reverse, unroll))(init, xs)


def _scan_in_blocks(f, init, xs, block: int, reverse: bool, unroll: int):
    """:func:`blocked_scan`'s loops, ``block`` checked."""
    length = jax.tree.leaves(xs)[0].shape[0]
    if block == 1:
        return jax.lax.scan(f, init, xs, reverse=reverse, unroll=unroll)
    blocks = length // block
    cut = blocks * block
    head = jax.tree.map(lambda a: a[:cut].reshape(blocks, block, *a.shape[1:]), xs)
    tail = jax.tree.map(lambda a: a[cut:], xs)

    def run_block(carry, block_xs):
        return jax.lax.scan(f, carry, block_xs, reverse=reverse, unroll=unroll)

    def run_head(carry):
        carry, ys = jax.lax.scan(run_block, carry, head, reverse=reverse)
        return carry, jax.tree.map(lambda a: a.reshape(cut, *a.shape[2:]), ys)

    if cut == length:
        return run_head(init)
    if reverse:
        carry, tail_ys = jax.lax.scan(f, init, tail, reverse=True, unroll=unroll)
        carry, head_ys = run_head(carry)
    else:
        carry, head_ys = run_head(init)
        carry, tail_ys = jax.lax.scan(f, carry, tail, unroll=unroll)
    return carry, jax.tree.map(lambda a, b: jnp.concatenate([a, b]), head_ys, tail_ys)


__all__ = ["SEQUENTIAL_BUFFER_BYTES", "block_size", "blocked_scan"]
