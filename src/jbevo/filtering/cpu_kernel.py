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
reductions). Anything else runs as it is. The call's
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

from collections.abc import Callable, Iterator
from functools import wraps
from typing import Any, TypeVar

import jax
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


def compiles_as_one_kernel(fn: Callable, *args: Any) -> bool:
    """True when every primitive of ``fn(*args)`` is in :data:`KERNEL_PRIMITIVES`."""
    return primitives(jax.make_jaxpr(fn)(*args).jaxpr) <= KERNEL_PRIMITIVES


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


__all__ = ["ELEMENTWISE_PRIMITIVES", "KERNEL_PRIMITIVES", "compiles_as_one_kernel", "one_kernel", "primitives"]
