"""Batches of sequences with the batch as the last axis, for the filters' one-kernel loops.

``jax.vmap`` puts the batch axis first: its batching rules move it to the front of every array
inside a ``lax.scan``. In a filter step compiled as one XLA:CPU kernel
(:mod:`jbevo.filtering.cpu_kernel`), the step's small sums and products (over sigma points and
state entries) then run over a non-contiguous batch and are not vectorised across it.
:func:`vmap_last` runs a function over a batch held in the *last* axis of every argument
instead: it evaluates the function's jaxpr for one element with each batched value carrying the
batch as its last (contiguous) axis, so the step's arithmetic is elementwise over the batch. The
result is compiled as one kernel where :func:`jbevo.filtering.cpu_kernel.one_kernel` allows.

It takes the primitives of :data:`jbevo.filtering.cpu_kernel.KERNEL_PRIMITIVES` except
``while``: elementwise arithmetic, shapes, slices (at unbatched indices), reductions, ``scan``,
``cond`` (on an unbatched index), nested ``jit`` and custom derivative rules (whose primal is
evaluated: derivatives are those of the primal code, as for any JAX function). Anything else
raises :class:`NotImplementedError` naming the primitive. The results equal ``jax.vmap``'s to
round-off (``tests/filtering/test_batch_last.py``); ``benchmarks/ukf.py`` measures the
speed (docs/filtering.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
from jax import lax
from jax.extend.core import Literal

from jbevo.filtering import cpu_kernel

_ELEMENTWISE = cpu_kernel.ELEMENTWISE_PRIMITIVES
_REDUCTIONS = frozenset("reduce_sum reduce_max reduce_min reduce_prod reduce_and reduce_or argmax argmin".split())
_CALLS = frozenset("pjit jit closed_call custom_jvp_call custom_vjp_call custom_vjp_call_jaxpr remat remat2 checkpoint".split())


def _batched(x: Any, is_batched: bool, size: int) -> jax.Array:
    """``x`` with the batch as its last axis (broadcast along it where ``x`` is unbatched)."""
    x = jnp.asarray(x)
    return x if is_batched else lax.broadcast_in_dim(x, (*x.shape, size), tuple(range(x.ndim)))


def _aligned(values: Sequence[Any], flags: Sequence[bool], size: int) -> list[jax.Array]:
    """An elementwise operation's operands, all batched; a rank-0 operand beside higher-rank ones
    is broadcast to their shape (lax broadcasts size-1 dimensions of equal ranks itself)."""
    shapes = [jnp.shape(v)[:-1] if b else jnp.shape(v) for v, b in zip(values, flags, strict=True)]
    rank = max(len(s) for s in shapes)
    target = next(s for s in shapes if len(s) == rank)
    out = []
    for v, b, shape in zip(values, flags, shapes, strict=True):
        if len(shape) == rank:
            out.append(_batched(v, b, size))
        else:
            dims = (rank,) if b else ()
            out.append(lax.broadcast_in_dim(jnp.asarray(v), (*target, size), dims))
    return out


def _sub_jaxpr(params: dict) -> Any:
    for key in ("jaxpr", "call_jaxpr", "fun_jaxpr"):
        if key in params:
            return params[key]
    raise NotImplementedError(f"vmap_last: a call without a jaxpr ({sorted(params)})")


def _evaluate(jaxpr: Any, consts: Sequence[Any], args: Sequence[Any], flags: Sequence[bool], size: int):
    """``jaxpr`` on ``args`` (``flags``: which carry the batch as their last axis): the outputs
    and their flags."""
    env: dict[Any, tuple[Any, bool]] = {}

    def read(var):
        return (var.val, False) if isinstance(var, Literal) else env[var]

    env.update({v: (c, False) for v, c in zip(jaxpr.constvars, consts, strict=True)})
    env.update({v: (a, f) for v, a, f in zip(jaxpr.invars, args, flags, strict=True)})
    for eqn in jaxpr.eqns:
        values, in_flags = zip(*(read(v) for v in eqn.invars), strict=True) if eqn.invars else ((), ())
        if not any(in_flags) and eqn.primitive.name not in _CALLS and eqn.primitive.name not in ("scan", "cond"):
            outs = eqn.primitive.bind(*values, **eqn.params)
            outs, out_flags = (outs, [False] * len(outs)) if eqn.primitive.multiple_results else ([outs], [False])
        else:
            outs, out_flags = _rule(eqn, list(values), list(in_flags), size)
        env.update({v: (o, f) for v, o, f in zip(eqn.outvars, outs, out_flags, strict=True)})
    results = [read(v) for v in jaxpr.outvars]
    return [r[0] for r in results], [r[1] for r in results]


def _rule(eqn: Any, values: list, flags: list[bool], size: int) -> tuple[list, list[bool]]:
    """One equation with a batched operand, the batch last."""
    name, p, prim = eqn.primitive.name, eqn.params, eqn.primitive
    if name in _ELEMENTWISE:
        return [prim.bind(*_aligned(values, flags, size), **p)], [True]
    if name in _REDUCTIONS or name in ("squeeze", "rev", "split", "unstack", "optimization_barrier"):
        # Their dimensions count from the front, so the batch axis last is untouched.
        values = [_batched(v, b, size) for v, b in zip(values, flags, strict=True)]
        outs = prim.bind(*values, **p)
        outs = list(outs) if prim.multiple_results else [outs]
        return outs, [True] * len(outs)
    if name in ("concatenate", "stack"):
        return [prim.bind(*[_batched(v, b, size) for v, b in zip(values, flags, strict=True)], **p)], [True]
    x = values[0]
    if name == "broadcast_in_dim":
        shape, dims = tuple(p["shape"]), tuple(p["broadcast_dimensions"])
        return [lax.broadcast_in_dim(x, (*shape, size), (*dims, len(shape)))], [True]
    if name == "reshape":
        return [lax.reshape(x, (*p["new_sizes"], size))], [True]
    if name == "transpose":
        perm = tuple(p["permutation"])
        return [lax.transpose(x, (*perm, len(perm)))], [True]
    if name == "slice":
        strides = None if p["strides"] is None else (*p["strides"], 1)
        return [lax.slice(x, (*p["start_indices"], 0), (*p["limit_indices"], size), strides)], [True]
    if name == "pad" and not flags[1]:
        return [lax.pad(x, values[1], (*p["padding_config"], (0, 0, 0)))], [True]
    if name == "dynamic_slice" and not any(flags[1:]):
        return [lax.dynamic_slice(x, [*values[1:], 0], (*p["slice_sizes"], size))], [True]
    if name == "dynamic_update_slice" and not any(flags[2:]):
        target, update = (_batched(v, b, size) for v, b in zip(values[:2], flags[:2], strict=True))
        return [lax.dynamic_update_slice(target, update, [*values[2:], 0])], [True]
    if name in _CALLS:
        sub = _sub_jaxpr(p)  # a closed jaxpr, or an open one (jax.checkpoint's)
        jaxpr, consts = (sub.jaxpr, sub.consts) if hasattr(sub, "consts") else (sub, ())
        return _evaluate(jaxpr, consts, values, flags, size)
    if name == "cond" and not flags[0]:
        return _cond(p["branches"], values, flags, size)
    if name == "scan":
        return _scan(p, values, flags, size)
    raise NotImplementedError(
        f"vmap_last cannot batch {name!r} with these operands (batched: {flags}); use jax.vmap for this function"
    )


def _cond(branches: Sequence[Any], values: list, flags: list[bool], size: int) -> tuple[list, list[bool]]:
    def branch(closed):
        def run(*operands):
            outs, out_flags = _evaluate(closed.jaxpr, closed.consts, operands, flags[1:], size)
            return [_batched(o, b, size) for o, b in zip(outs, out_flags, strict=True)]

        return run

    outs = lax.switch(values[0], [branch(b) for b in branches], *values[1:])
    return outs, [True] * len(outs)


def _scan(p: dict, values: list, flags: list[bool], size: int) -> tuple[list, list[bool]]:
    """``lax.scan`` with every carry batched; ``xs`` keep their leading time axis."""
    body, n_consts, n_carry = p["jaxpr"], p["num_consts"], p["num_carry"]
    consts, init, xs = values[:n_consts], values[n_consts : n_consts + n_carry], values[n_consts + n_carry :]
    const_flags, xs_flags = flags[:n_consts], flags[n_consts + n_carry :]
    init = [_batched(c, b, size) for c, b in zip(init, flags[n_consts : n_consts + n_carry], strict=True)]

    def step(carry, x):
        body_flags = [*const_flags, *([True] * n_carry), *xs_flags]
        outs, out_flags = _evaluate(body.jaxpr, body.consts, [*consts, *carry, *x], body_flags, size)
        outs = [_batched(o, b, size) for o, b in zip(outs, out_flags, strict=True)]
        return outs[:n_carry], outs[n_carry:]

    carry, ys = lax.scan(step, init, xs, length=p["length"], reverse=p["reverse"], unroll=p["unroll"])
    return [*carry, *ys], [True] * (n_carry + len(ys))


def _kernel_group(run_group: Callable[[int], Callable], examples: list, size: int) -> int:
    """The batch itself where it compiles as one kernel; else the largest group of sequences
    (halving from the batch) that does; the batch where not even one sequence does."""
    group = size
    while group >= 1:
        shapes = [jax.ShapeDtypeStruct((*e.shape, group), e.dtype) for e in examples]
        if cpu_kernel.compiles_as_one_kernel(run_group(group), *shapes):
            return group
        group //= 2
    return size


def vmap_last(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` over a batch held in the last axis of every argument leaf (all leaves batched, of
    one batch size); every output leaf has the batch as its last axis. Compiled as one XLA:CPU
    kernel where :func:`jbevo.filtering.cpu_kernel.one_kernel` allows. Its operations grow with
    the batch: a batch too large for one kernel (the localization UKF over more than 65
    sequences) runs as a loop over groups that fit (halving the batch until one does; the last
    group padded with copies of the first sequence). For the filters, pass
    ``one_kernel=False`` inside ``fn`` (the whole batched function becomes the kernel) and
    ``check_inputs=False`` (their input checks factorise Q, R and P with LAPACK and raise through
    host callbacks, neither of which this batches: :class:`NotImplementedError`).

    Example, 64 sequences of ``T`` steps: ``vmap_last(lambda x0, u, z: ukf.filter(model,
    GaussianState(x0, P0), u, z, Q, R, one_kernel=False).filtered_mean)`` on ``x0`` of shape
    ``(3, 64)``, ``u`` and ``z`` of shape ``(T, 3, 64)`` gives means of shape ``(T, 3, 64)``.
    """

    def batched(*args):
        leaves, tree = jax.tree.flatten(args)
        if not leaves:
            raise ValueError("vmap_last needs at least one array argument")
        sizes = {jnp.shape(leaf)[-1] if jnp.ndim(leaf) else None for leaf in leaves}
        size = sizes.pop() if len(sizes) == 1 else None
        if size is None:
            raise ValueError(f"vmap_last: every argument needs the same batch size as its last axis, got {sizes or {None}}")

        def one(*flat):
            return fn(*jax.tree.unflatten(tree, flat))

        examples = [jax.ShapeDtypeStruct(jnp.shape(leaf)[:-1], jnp.result_type(leaf)) for leaf in leaves]
        closed, out_shapes = jax.make_jaxpr(one, return_shape=True)(*examples)
        out_tree = jax.tree.structure(out_shapes)

        def run_group(group: int) -> Callable[..., list]:
            def run(*flat):
                outs, flags = _evaluate(closed.jaxpr, closed.consts, flat, [True] * len(flat), group)
                return [_batched(o, b, group) for o, b in zip(outs, flags, strict=True)]

            return run

        group = _kernel_group(run_group, examples, size)
        if group == size:
            return jax.tree.unflatten(out_tree, cpu_kernel.one_kernel(run_group(size))(*leaves))
        # Groups of ``group`` sequences, one kernel each, in a loop over the groups (the batch
        # padded with copies of its first sequence to a whole number of groups).
        count = -(-size // group)
        padded = [jnp.concatenate([leaf, jnp.repeat(leaf[..., :1], count * group - size, axis=-1)], axis=-1) for leaf in leaves]
        grouped = [jnp.moveaxis(leaf.reshape(*leaf.shape[:-1], count, group), -2, 0) for leaf in padded]
        outs = jax.lax.map(lambda chunk: cpu_kernel.one_kernel(run_group(group))(*chunk), grouped)
        outs = [jnp.moveaxis(o, 0, -2).reshape(*o.shape[1:-1], count * group)[..., :size] for o in outs]
        return jax.tree.unflatten(out_tree, outs)

    return batched


__all__ = ["vmap_last"]
