"""A loop of small steps compiled as one XLA:CPU kernel.

XLA:CPU runs a compiled program as a sequence of kernels ("thunks"), and a ``while`` loop (a
``lax.scan``) as its body's kernels on every iteration, each one called, and with more than a
few small buffers scheduled as a dependency graph (:mod:`jbevo.filtering.blocked_scan`). A
filter step of a 3-state model is a few dozen kernels of a few numbers each, so the calls and
the scheduling, not the arithmetic, set its speed. XLA:CPU can also emit a whole computation as
one function, in which the loop is a loop of machine code: it does so for calls whose frontend
attribute ``xla_cpu_small_call`` is ``"true"`` (its own ``SmallWhileLoopHoistingPass`` tags small
loops that way). :func:`one_kernel` puts a function in such a call: a nested ``jit`` carrying
that attribute and ``inlineable="false"`` (so that XLA's call inliner keeps it), by
``jax.experimental.xla_metadata.set_xla_metadata``.

That path cannot run everything. A custom call (LAPACK, FFT, host callbacks), a scatter, a sort
and others need a runtime that the one-function path does not link, and a matrix product that
XLA keeps as a dot is a fusion kind it does not emit (the compilation fails).
:func:`one_kernel` therefore wraps a function only when every primitive of its jaxpr (nested
jaxprs included) is in :data:`KERNEL_PRIMITIVES`: elementwise arithmetic, broadcasting, slicing,
reductions and control flow, whose transposes and batched forms stay in the same set (no
``gather``: its transpose is a scatter; no ``dot_general``: jbevo's filters sum sigma points by
reductions). Nor does it run large operations: XLA:CPU gives a float reduction in a loop of
4,096 elements or more to YNNPACK, which it cannot call, and larger elementwise work fails to
compile too. A vmapped step is as large as its batch, so the wrapper also bounds every
operation's size times the batch of the enclosing ``vmap`` s (:func:`batch_size`;
:data:`LARGE_REDUCTION`, :data:`LARGE_OPERATION`, :data:`LARGE_OUTSIDE_LOOPS`): the UKF of the
localization model keeps the call vmapped over up to 65 sequences and runs as the plain loop
over more. Anything else runs as it is. The call's
operands pass an ``optimization_barrier`` first: an operand that XLA has folded into a large
constant (data computed inside ``jit`` from constants alone, say a 500-step sequence) otherwise
gets a buffer the one-function call cannot address, and the compiler aborts the process on a
failed check (jax 0.10.2; the tests hold such cases). Only the lowering for the CPU is changed
(``jax.lax.platform_dependent``); other backends get the function itself.

The results are those of the plain program to round-off (the kernel's code is generated
differently; ``tests/filtering/test_cpu_kernel.py``), and it works under ``jit``, ``vmap`` and
``grad``. ``benchmarks/ukf.py`` measures it on the localization UKF (docs/filtering.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from functools import wraps
from typing import Any, TypeVar

import jax
from jax._src.core import Tracer
from jax._src.interpreters import ad, batching
from jax._src.interpreters import partial_eval as pe
from jax.experimental.xla_metadata import set_xla_metadata

F = TypeVar("F", bound=Callable[..., Any])

#: Elementwise primitives (``stop_gradient`` included): one output element from the same element
#: of each operand.
ELEMENTWISE_PRIMITIVES = frozenset(
    {
        *"abs acos acosh add and asin asinh atan atan2 atanh cbrt ceil clamp convert_element_type".split(),
        *"copy copy_p cos cosh div eq exp exp2 expm1 floor ge gt integer_pow is_finite le log log1p".split(),
        *"logistic lt max min mul ne neg not or pow rem round rsqrt select_n sign sin sinh sqrt".split(),
        *"square sub tan tanh xor erf erfc erf_inv nextafter stop_gradient".split(),
    }
)

#: Primitives that the one-function path of XLA:CPU compiles, with their derivatives and batched
#: forms; a function with any other primitive is not wrapped.
KERNEL_PRIMITIVES = ELEMENTWISE_PRIMITIVES | frozenset(
    {
        # shapes, slices, reductions, products
        *"broadcast_in_dim reshape squeeze expand_dims slice dynamic_slice dynamic_update_slice".split(),
        *"concatenate stack unstack pad transpose rev iota split reduce_sum reduce_max reduce_min reduce_prod".split(),
        *"reduce_and reduce_or argmax argmin".split(),
        # control flow and calls (their jaxprs are checked too)
        *"scan while cond pjit jit closed_call custom_jvp_call custom_vjp_call custom_vjp_call_jaxpr".split(),
        *"remat checkpoint optimization_barrier".split(),
    }
)


def _sub_jaxprs(value: Any) -> Iterator[Any]:
    """The jaxprs held in an equation parameter (a jaxpr, a closed jaxpr, or a tuple of them)."""
    if hasattr(value, "eqns"):
        yield value
    elif hasattr(value, "jaxpr") and hasattr(value.jaxpr, "eqns"):
        yield value.jaxpr
    elif isinstance(value, tuple | list):
        for item in value:
            yield from _sub_jaxprs(item)


def primitives(jaxpr: Any) -> set[str]:
    """The names of every primitive in ``jaxpr`` and the jaxprs nested in its equations."""
    names: set[str] = set()
    for eqn in jaxpr.eqns:
        names.add(eqn.primitive.name)
        for value in eqn.params.values():
            for sub in _sub_jaxprs(value):
                names |= primitives(sub)
    return names


#: Inside a loop, XLA:CPU hands a float (or 8-bit integer) sum, max or min reduction with an
#: operand or a result of at least this many elements to YNNPACK
#: (``xla/backends/cpu/ynn_support.cc``, ``kMinElements``), which the one-function path cannot
#: run: compiling fails ("Fusion kind not implemented on CPU").
LARGE_REDUCTION = 4096

#: Any other operation this large inside a loop may fail too ("Failed to materialize symbols";
#: measured with jax 0.10.2: an elementwise step of 27,500 elements compiles, one of 41,250 does
#: not), so the bound is set below both.
LARGE_OPERATION = 16384

#: The same outside the loops (measured: 320,000 elements compile, 1,100,000 do not).
LARGE_OUTSIDE_LOOPS = 500_000

#: Primitives that only move data: their operands may be large (the loop's stacked inputs and
#: outputs, sliced and updated in place).
_MOVES_DATA = frozenset(
    "slice dynamic_slice dynamic_update_slice squeeze expand_dims reshape copy copy_p optimization_barrier".split()
)
_LOOPS = frozenset({"scan", "while"})
_YNN_REDUCTIONS = frozenset({"reduce_sum", "reduce_max", "reduce_min"})
_YNN_TYPES = frozenset({"float64", "float32", "float16", "bfloat16", "int8", "uint8"})


def batch_size(*args: Any) -> int:
    """The number of copies ``vmap`` makes of a value among ``args`` (the product over nested
    ``vmap`` s; 1 outside any): the tracers of ``vmap``, and of ``jvp``, ``grad`` and ``jit``
    around or inside it, are unwrapped to find them."""
    largest = 1
    for leaf in jax.tree.leaves(args):
        size, value = 1, leaf
        while isinstance(value, Tracer):
            if isinstance(value, batching.BatchTracer):
                if isinstance(value.batch_dim, int):
                    size *= value.val.shape[value.batch_dim]
                value = value.val
            elif isinstance(value, pe.JaxprTracer):
                value = value.pval.get_known()
            elif isinstance(value, ad.JVPTracer | ad.LinearizeTracer):
                value = value.primal
            else:  # jit's tracer: nothing inside
                break
        largest = max(largest, size)
    return largest


def _largest_operations(jaxpr: Any, in_loop: bool = False) -> tuple[int, int, int]:
    """The most elements of an operand or result of ``jaxpr``'s equations (nested jaxprs
    included, leaving out those that hold jaxprs and those that only move data): of a reduction
    that XLA:CPU gives YNNPACK in a loop, of any other operation in a loop, and of any operation
    outside the loops."""
    reduction = other = outside = 0
    for eqn in jaxpr.eqns:
        subs = [sub for value in eqn.params.values() for sub in _sub_jaxprs(value)]
        if subs:
            for sub in subs:
                found = _largest_operations(sub, in_loop or eqn.primitive.name in _LOOPS)
                reduction, other, outside = max(reduction, found[0]), max(other, found[1]), max(outside, found[2])
            continue
        if eqn.primitive.name in _MOVES_DATA:
            continue
        size = max(math.prod(getattr(var.aval, "shape", ())) for var in (*eqn.invars, *eqn.outvars))
        dtype = str(getattr(eqn.invars[0].aval, "dtype", "")) if eqn.invars else ""
        if not in_loop:
            outside = max(outside, size)
        elif eqn.primitive.name in _YNN_REDUCTIONS and dtype in _YNN_TYPES:
            reduction = max(reduction, size)
        else:
            other = max(other, size)
    return reduction, other, outside


def compiles_as_one_kernel(fn: Callable, *args: Any) -> bool:
    """True when every primitive of ``fn(*args)`` is in :data:`KERNEL_PRIMITIVES` and its
    operations, times the batch of enclosing ``vmap`` s, stay below :data:`LARGE_REDUCTION`,
    :data:`LARGE_OPERATION` and :data:`LARGE_OUTSIDE_LOOPS`."""
    jaxpr = jax.make_jaxpr(fn)(*args).jaxpr
    if not primitives(jaxpr) <= KERNEL_PRIMITIVES:
        return False
    reduction, other, outside = _largest_operations(jaxpr)
    copies = batch_size(*args)
    return reduction * copies < LARGE_REDUCTION and other * copies < LARGE_OPERATION and outside * copies < LARGE_OUTSIDE_LOOPS


def one_kernel(fn: F) -> F:
    """``fn``, compiled as one XLA:CPU kernel where it can be (module docstring); unchanged on
    other backends and where a primitive is outside :data:`KERNEL_PRIMITIVES`."""

    @wraps(fn)
    def wrapped(*args):
        if not compiles_as_one_kernel(fn, *args):
            return fn(*args)

        def on_cpu(*cpu_args):
            with set_xla_metadata(xla_cpu_small_call="true", inlineable="false"):
                # The barrier keeps folded constants out of the call's operands (module docstring).
                return jax.jit(fn)(*jax.lax.optimization_barrier(cpu_args))

        return jax.lax.platform_dependent(*args, cpu=on_cpu, default=fn)

    return wrapped  # type: ignore[return-value]


__all__ = [
    "ELEMENTWISE_PRIMITIVES",
    "KERNEL_PRIMITIVES",
    "LARGE_OPERATION",
    "LARGE_OUTSIDE_LOOPS",
    "LARGE_REDUCTION",
    "batch_size",
    "compiles_as_one_kernel",
    "one_kernel",
    "primitives",
]
