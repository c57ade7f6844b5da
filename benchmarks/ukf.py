"""UKF speed and agreement: jbevo vs dynamax 1.0.3 vs cuthbertlib 0.1.1 vs filterpy 2.0.0, same data, same process.

The BEVO+ localization model: state (x, y, yaw), control the body-frame odometry increment,
measurement the pose itself with yaw wrapped; T = 5,000 steps; alpha = 1, beta = 2, kappa = 0;
float64. jbevo's covariance and square-root filters, and its filter plus unscented RTS smoother
against dynamax's unscented Kalman smoother; cuthbert has no unscented filter of its own, so its
peer is one composed of cuthbertlib's parts (unscented statistical linear regression,
``quadrature.linearize.functional``, feeding its square-root Kalman predict / update and RTS
steps in a ``lax.scan``); the square-root filter with its ``tria``
(unrolled modified Gram-Schmidt) against the same filter with LAPACK's QR in its place; and
jbevo's loops in blocks (``block="auto"``) against one ``lax.scan``: the filters, the smoother,
vmapped, and the gradient of the log-likelihood (with compile times); and batches held in the
last axis (``filtering.batch_last.vmap_last``: filter, smoother and the gradient) against
``jax.vmap``. The methods are timed in interleaved rounds (best of ``--repeats``), the whole
measurement repeated ``--runs`` times (the JSON keeps every run; its top-level figures are the
medians over the runs). Writes ``benchmarks/results/ukf.json`` and prints a table.

    python benchmarks/ukf.py [--steps 5000] [--batch 64] [--repeats 15] [--runs 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from functools import partial
from pathlib import Path
from unittest import mock

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jbevo.data.synthetic.planar import simulate_planar_sequence  # noqa: E402
from jbevo.files import write_json_atomic  # noqa: E402
from jbevo.filtering import smoother, sqrt_ukf, ukf  # noqa: E402
from jbevo.filtering.batch_last import vmap_last  # noqa: E402
from jbevo.filtering.planar import planar_pose_model  # noqa: E402
from jbevo.filtering.unscented import MerweScaled  # noqa: E402
from jbevo.geometry import sincos, wrap_angle  # noqa: E402
from timing import best_seconds_interleaved  # noqa: E402

ALPHA, BETA, KAPPA = 1.0, 2.0, 0.0
Q = np.diag([0.02, 0.01, 0.005]) ** 2
R = np.diag([0.5, 0.5, 0.05]) ** 2
P0 = np.diag([1.0, 1.0, 0.1]) ** 2


# --------------------------------------------------------------------------------- jbevo


def make_filter(check_inputs: bool = True, form=ukf, block=1, one_kernel: bool = True):
    """jbevo's filter (``form``: :mod:`ukf` or :mod:`sqrt_ukf`) on the benchmark's model, its loop
    in blocks of ``block`` steps (1: one ``lax.scan``, ``"auto"``): ``run(x0, increments, fixes)
    -> FilterResult``."""
    model = planar_pose_model()
    scheme = MerweScaled(ALPHA, BETA, KAPPA)

    def run(x0, increments, fixes):
        prior = ukf.GaussianState(x0, jnp.asarray(P0))
        return form.filter(
            model,
            prior,
            increments,
            fixes,
            jnp.asarray(Q),
            jnp.asarray(R),
            scheme=scheme,
            check_inputs=check_inputs,
            block=block,
            one_kernel=one_kernel,
        )

    return run


def make_jbevo(check_inputs: bool, form=ukf, smoothed: bool = False, block=1, one_kernel: bool = True):
    """:func:`make_filter`'s filter, optionally followed by the RTS smoother:
    ``run(x0, increments, fixes) -> (means, covariances or factors)``."""
    run_filter = make_filter(check_inputs, form, block, one_kernel)

    def run(x0, increments, fixes):
        res = run_filter(x0, increments, fixes)
        if smoothed:
            model, scheme = planar_pose_model(), MerweScaled(ALPHA, BETA, KAPPA)
            sm = smoother.smooth(model, res, increments, jnp.asarray(Q), scheme=scheme, block=block, one_kernel=one_kernel)
            return sm.smoothed_mean, sm.smoothed_cov
        return res[0], res[1]

    return run


def make_log_likelihood(block=1, one_kernel: bool = True, check_inputs: bool = True):
    """The covariance filter's log-likelihood of one sequence, ``(x0, increments, fixes) ->
    scalar``, its loop in blocks of ``block`` steps."""
    run_filter = make_filter(check_inputs, ukf, block, one_kernel)
    return lambda x0, increments, fixes: run_filter(x0, increments, fixes).log_likelihood


def make_grad(block, one_kernel: bool = True):
    """The gradient of the covariance filter's log-likelihood with respect to the initial mean
    (the cost of learning through the filter), its loop in blocks of ``block`` steps."""
    return jax.jit(jax.grad(make_log_likelihood(block, one_kernel)))


def dynamax_start(x0, increments, fixes):
    """dynamax's starting beliefs and fixes for a batch of sequences. dynamax updates first, then
    predicts step t + 1 with inputs[t + 1]: it starts from jbevo's first prediction, so that its
    filtered means are jbevo's; its yaw is averaged linearly, so its fixes' yaw is unwrapped."""

    def first_prediction(mean, u):
        prior = ukf.GaussianState(mean, jnp.asarray(P0))
        return ukf.predict(planar_pose_model(), prior, u, jnp.asarray(Q), MerweScaled(ALPHA, BETA, KAPPA))

    pred0 = jax.vmap(first_prediction)(x0, increments[:, 0])
    return pred0, fixes.at[..., 2].set(jnp.unwrap(fixes[..., 2], axis=-1))


def small_calls(fn, *args) -> int:
    """How many one-kernel calls the jitted ``fn``'s compiled program for ``args`` holds."""
    return fn.lower(*args).compile().as_text().count('xla_cpu_small_call="true"')


def compile_seconds(fn, *args) -> float:
    """Seconds to lower and compile the jitted ``fn`` for ``args`` (not cached: a fresh compile)."""
    t0 = time.perf_counter()
    fn.lower(*args).compile()
    return time.perf_counter() - t0


def tria_lapack(a):
    """``tria`` by LAPACK's QR (the library route the unrolled code replaces)."""
    r = jnp.linalg.qr(a.T, mode="r")
    return (r * jnp.where(jnp.diagonal(r) < 0, -1.0, 1.0)[:, None]).T


def with_lapack_tria(run, *args):
    """``run`` jitted with :func:`tria_lapack` in place of ``sqrt_ukf.tria``: traced once here
    under the patch, later calls reuse that compilation. It is jitted as a function of its own
    code: ``jax.jit`` reuses a trace for another function of the same code and closure, which
    would give the patched program to the plain one or the other way round."""

    def lapack_tria_run(*a):
        return run(*a)

    jitted = jax.jit(lapack_tria_run)
    with mock.patch.object(sqrt_ukf, "tria", tria_lapack):
        jax.block_until_ready(jitted(*args))
    return jitted


# --------------------------------------------------------------------------- cuthbertlib


def make_cuthbertlib_runner(smoothed: bool = False):
    """The square-root unscented filter (and RTS smoother) built from cuthbertlib's parts: each
    step statistically linearises the motion (and then the measurement) with its unscented
    quadrature and runs its square-root Kalman step on the result. Like dynamax it averages
    angles linearly, so it runs on unwrapped yaw: ``run(x0, increments, fixes) -> (means, factors)``."""
    from cuthbertlib.kalman import filter_update, predict, smoother_update
    from cuthbertlib.quadrature import unscented
    from cuthbertlib.quadrature.linearize import functional

    quadrature = unscented.weights(3, alpha=ALPHA, beta=BETA, kappa=KAPPA)
    # cuthbertlib 0.1.1 averages the noise covariance over the sigma points with the covariance
    # weights, which sum to 1 + (1 - alpha^2 + beta) = 3 here, not 1: an additive noise given to it
    # comes out tripled. The factors are scaled so that it returns Q and R themselves.
    unbias = 1.0 / jnp.sqrt(jnp.sum(quadrature.wc))
    chol_q = unbias * jnp.linalg.cholesky(jnp.asarray(Q))
    chol_r = unbias * jnp.linalg.cholesky(jnp.asarray(R))

    def motion(u):
        def f(x):
            s, c = jnp.sin(x[2]), jnp.cos(x[2])
            return jnp.stack([x[0] + c * u[0] - s * u[1], x[1] + s * u[0] + c * u[1], x[2] + u[2]])

        return f

    def filter_step(carry, inputs):
        m, chol = carry
        u, z = inputs
        F, c, chol_q_lin = functional(motion(u), chol_q, m, chol, quadrature, mode="cholesky")
        m, chol = predict(m, chol, F, c, chol_q_lin)
        H, d, chol_r_lin = functional(lambda x: x, chol_r, m, chol, quadrature, mode="cholesky")
        (m, chol), _ = filter_update(m, chol, H, d, chol_r_lin, z)
        return (m, chol), (m, chol)

    def smoother_step(carry, inputs):
        sm, s_chol = carry
        m, chol, u_next = inputs
        F, c, chol_q_lin = functional(motion(u_next), chol_q, m, chol, quadrature, mode="cholesky")
        (sm, s_chol), _ = smoother_update(m, chol, sm, s_chol, F, c, chol_q_lin)
        return (sm, s_chol), (sm, s_chol)

    def run(x0, increments, fixes):
        init = (x0, jnp.linalg.cholesky(jnp.asarray(P0)))
        _, (means, factors) = jax.lax.scan(filter_step, init, (increments, fixes))
        if not smoothed:
            return means, factors
        last = (means[-1], factors[-1])
        _, (sm, s_chol) = jax.lax.scan(smoother_step, last, (means[:-1], factors[:-1], increments[1:]), reverse=True)
        return jnp.concatenate([sm, means[-1:]]), jnp.concatenate([s_chol, factors[-1:]])

    return run


# ------------------------------------------------------------------------------ filterpy


def run_filterpy(x0, increments, fixes):
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    def residual(a, b):
        d = np.subtract(a, b)
        d[2] = (d[2] + np.pi) % (2 * np.pi) - np.pi
        return d

    def add(x, dx):
        s = np.add(x, dx)
        s[2] = (s[2] + np.pi) % (2 * np.pi) - np.pi
        return s

    def mean(points, w):
        m = w @ points
        ref = points[0, 2]
        m[2] = ref + w @ ((points[:, 2] - ref + np.pi) % (2 * np.pi) - np.pi)
        m[2] = (m[2] + np.pi) % (2 * np.pi) - np.pi
        return m

    def fx(x, dt, u):
        return np.asarray(se2_compose_np(x, u))

    points = MerweScaledSigmaPoints(3, ALPHA, BETA, KAPPA, subtract=residual)
    f = UnscentedKalmanFilter(
        3,
        3,
        1.0,
        lambda x: x,
        fx,
        points,
        x_mean_fn=mean,
        z_mean_fn=mean,
        residual_x=residual,
        residual_z=residual,
        state_add=add,
    )
    f.x, f.P, f.Q, f.R = np.array(x0, float), P0.copy(), Q.copy(), R.copy()
    means = np.empty((len(fixes), 3))
    for t in range(len(fixes)):
        f.predict(u=increments[t])
        f.update(fixes[t])
        means[t] = f.x
    return means


def se2_compose_np(x, u):
    c, s = np.cos(x[2]), np.sin(x[2])
    return np.array([x[0] + c * u[0] - s * u[1], x[1] + s * u[0] + c * u[1], (x[2] + u[2] + np.pi) % (2 * np.pi) - np.pi])


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=15, help="interleaved rounds per run (the best counts)")
    parser.add_argument("--runs", type=int, default=5, help="independent runs (the JSON keeps each; top-level keys are medians)")
    parser.add_argument("--filterpy-steps", type=int, default=None, help="filterpy runs this many steps (default all)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "ukf.json")
    args = parser.parse_args(argv)
    steps, batch = args.steps, args.batch

    keys = jax.random.split(jax.random.PRNGKey(0), batch)
    seqs = jax.vmap(lambda k: simulate_planar_sequence(k, steps, yaw_rate_std=0.1))(keys)
    x0 = seqs.poses[:, 0] + jnp.array([0.5, -0.5, 0.05])
    one = jax.tree.map(lambda a: a[0], seqs)

    jb_single = jax.jit(make_jbevo(check_inputs=False))
    jb_checked = jax.jit(make_jbevo(check_inputs=True))
    jb_batch = jax.jit(jax.vmap(make_jbevo(check_inputs=False)))
    sqrt_single = jax.jit(make_jbevo(check_inputs=False, form=sqrt_ukf))
    sqrt_batch = jax.jit(jax.vmap(make_jbevo(check_inputs=False, form=sqrt_ukf)))
    smooth_single = jax.jit(make_jbevo(check_inputs=False, smoothed=True))
    smooth_batch = jax.jit(jax.vmap(make_jbevo(check_inputs=False, smoothed=True)))
    sqrt_lapack = with_lapack_tria(make_jbevo(check_inputs=False, form=sqrt_ukf), x0[0], one.increments, one.fixes)
    # The loops in blocks whose buffers stay small (``block="auto"``), and gradients of the
    # log-likelihood with respect to the initial mean, with and without blocks.
    blocked = {
        "jbevo_single_blocked": jax.jit(make_jbevo(check_inputs=False, block="auto")),
        "jbevo_sqrt_single_blocked": jax.jit(make_jbevo(check_inputs=False, form=sqrt_ukf, block="auto")),
        "jbevo_smoother_single_blocked": jax.jit(make_jbevo(check_inputs=False, smoothed=True, block="auto")),
    }
    jb_batch_blocked = jax.jit(jax.vmap(make_jbevo(check_inputs=False, block="auto")))
    grads = {f"jbevo_grad_single{suffix}": make_grad(block) for suffix, block in (("", 1), ("_blocked", "auto"))}
    # The same programs with plain XLA:CPU loops (each loop not compiled as one kernel).
    single_args = (x0[0], one.increments, one.fixes)
    plain_loops = {
        "jbevo_single_plain_loop": jax.jit(make_jbevo(check_inputs=False, one_kernel=False)),
        "jbevo_sqrt_single_plain_loop": jax.jit(make_jbevo(check_inputs=False, form=sqrt_ukf, one_kernel=False)),
        "jbevo_smoother_single_plain_loop": jax.jit(make_jbevo(check_inputs=False, smoothed=True, one_kernel=False)),
        "jbevo_grad_single_plain_loop": make_grad(1, one_kernel=False),
    }
    jb_batch_plain = jax.jit(jax.vmap(make_jbevo(check_inputs=False, one_kernel=False)))
    # The batch as every array's last axis (vmap_last compiles the whole as one kernel itself),
    # and the gradient of the summed log-likelihoods with respect to the initial means.
    leading = (x0, seqs.increments, seqs.fixes)
    trailing = tuple(jnp.moveaxis(a, 0, -1) for a in leading)
    batch_last = {
        "jbevo_batch_last64": jax.jit(vmap_last(make_jbevo(check_inputs=False, one_kernel=False))),
        "jbevo_smoother_batch_last64": jax.jit(vmap_last(make_jbevo(check_inputs=False, smoothed=True, one_kernel=False))),
        "jbevo_grad_batch_last64": jax.jit(
            jax.grad(lambda *a: jnp.sum(vmap_last(make_log_likelihood(one_kernel=False, check_inputs=False))(*a)))
        ),
    }
    grad_batch = jax.jit(jax.grad(lambda *a: jnp.sum(jax.vmap(make_log_likelihood(check_inputs=False))(*a))))
    results_compile = {
        f"compile_s_{name}": compile_seconds(fn, x0[0], one.increments, one.fixes)
        for name, fn in (
            ("filter", jb_single),
            ("filter_blocked", blocked["jbevo_single_blocked"]),
            ("grad", grads["jbevo_grad_single"]),
            ("grad_blocked", grads["jbevo_grad_single_blocked"]),
        )
    }
    results_compile["compile_s_filter_plain_loop"] = compile_seconds(plain_loops["jbevo_single_plain_loop"], *single_args)
    results_compile["compile_s_grad_plain_loop"] = compile_seconds(plain_loops["jbevo_grad_single_plain_loop"], *single_args)
    # Each loop is one kernel by default, and a plain loop with one_kernel=False or LAPACK's QR.
    if jax.default_backend() == "cpu":
        assert small_calls(jb_single, *single_args) > 0 and small_calls(sqrt_single, *single_args) > 0
        assert small_calls(plain_loops["jbevo_single_plain_loop"], *single_args) == small_calls(sqrt_lapack, *single_args) == 0

    pred0, fixes_unwrapped = dynamax_start(x0, seqs.increments, seqs.fixes)
    dyn_inputs = seqs.increments
    dyn = make_dynamax_runner()
    dyn_single = jax.jit(lambda m, P, u, z: dyn(m, P, u, z))
    dyn_batch = jax.jit(jax.vmap(lambda m, P, u, z: dyn(m, P, u, z)))
    uks = make_dynamax_runner(smoothed=True)
    uks_single = jax.jit(lambda m, P, u, z: uks(m, P, u, z))
    uks_batch = jax.jit(jax.vmap(lambda m, P, u, z: uks(m, P, u, z)))

    cb = make_cuthbertlib_runner()
    cb_single, cb_batch = jax.jit(cb), jax.jit(jax.vmap(cb))
    cb_uks = make_cuthbertlib_runner(smoothed=True)
    cb_uks_single, cb_uks_batch = jax.jit(cb_uks), jax.jit(jax.vmap(cb_uks))

    results: dict = {"T": steps, "batch": batch, "dtype": "float64", "alpha": ALPHA, "beta": BETA, "kappa": KAPPA}
    # dynamax given jbevo's sincos: how much of the lead is the vectorisable trig.
    dyn_sc = jax.jit(jax.vmap(make_dynamax_runner(trig=sincos)))
    timings = {
        "single": {
            "jbevo_single": lambda: jb_single(x0[0], one.increments, one.fixes),
            "jbevo_single_checked": lambda: jb_checked(x0[0], one.increments, one.fixes),
            "dynamax_single": lambda: dyn_single(pred0.mean[0], pred0.cov[0], dyn_inputs[0], fixes_unwrapped[0]),
            "jbevo_sqrt_single": lambda: sqrt_single(x0[0], one.increments, one.fixes),
            "jbevo_smoother_single": lambda: smooth_single(x0[0], one.increments, one.fixes),
            "dynamax_uks_single": lambda: uks_single(pred0.mean[0], pred0.cov[0], dyn_inputs[0], fixes_unwrapped[0]),
            "jbevo_sqrt_single_lapack_qr": lambda: sqrt_lapack(x0[0], one.increments, one.fixes),
            "cuthbertlib_single": lambda: cb_single(x0[0], one.increments, fixes_unwrapped[0]),
            "cuthbertlib_uks_single": lambda: cb_uks_single(x0[0], one.increments, fixes_unwrapped[0]),
            **{name: partial(fn, *single_args) for name, fn in (blocked | grads | plain_loops).items()},
        },
        "batched": {
            "jbevo_vmap64": lambda: jb_batch(x0, seqs.increments, seqs.fixes),
            "dynamax_vmap64": lambda: dyn_batch(pred0.mean, pred0.cov, dyn_inputs, fixes_unwrapped),
            "dynamax_vmap64_sincos": lambda: dyn_sc(pred0.mean, pred0.cov, dyn_inputs, fixes_unwrapped),
            "jbevo_sqrt_vmap64": lambda: sqrt_batch(x0, seqs.increments, seqs.fixes),
            "jbevo_smoother_vmap64": lambda: smooth_batch(x0, seqs.increments, seqs.fixes),
            "dynamax_uks_vmap64": lambda: uks_batch(pred0.mean, pred0.cov, dyn_inputs, fixes_unwrapped),
            "cuthbertlib_vmap64": lambda: cb_batch(x0, seqs.increments, fixes_unwrapped),
            "cuthbertlib_uks_vmap64": lambda: cb_uks_batch(x0, seqs.increments, fixes_unwrapped),
            "jbevo_vmap64_blocked": lambda: jb_batch_blocked(x0, seqs.increments, seqs.fixes),
            "jbevo_vmap64_plain_loop": lambda: jb_batch_plain(x0, seqs.increments, seqs.fixes),
            "jbevo_batch_last64": partial(batch_last["jbevo_batch_last64"], *trailing),
            "jbevo_smoother_batch_last64": partial(batch_last["jbevo_smoother_batch_last64"], *trailing),
        },
        # Gradients over the batch in rounds of their own (their large buffers slow what runs
        # beside them).
        "batched_gradients": {
            "jbevo_grad_vmap64": lambda: grad_batch(*leading),
            "jbevo_grad_batch_last64": partial(batch_last["jbevo_grad_batch_last64"], *trailing),
        },
    }
    # Independent runs of the whole measurement: this shared VM's speed varies between them.
    runs = []
    for _ in range(args.runs):
        run = {name: steps / t for name, t in best_seconds_interleaved(timings["single"], args.repeats).items()}
        for group in ("batched", "batched_gradients"):
            run |= {name: batch * steps / t for name, t in best_seconds_interleaved(timings[group], args.repeats).items()}
        run["speedup_single_vs_dynamax"] = run["jbevo_single"] / run["dynamax_single"]
        run["speedup_vmap64_vs_dynamax"] = run["jbevo_vmap64"] / run["dynamax_vmap64"]
        run["speedup_vmap64_vs_dynamax_sincos"] = run["jbevo_vmap64"] / run["dynamax_vmap64_sincos"]
        for kind in ("single", "vmap64"):
            run[f"sqrt_slowdown_{kind}"] = run[f"jbevo_{kind}"] / run[f"jbevo_sqrt_{kind}"]
            run[f"smoother_speedup_{kind}_vs_dynamax"] = run[f"jbevo_smoother_{kind}"] / run[f"dynamax_uks_{kind}"]
            run[f"sqrt_speedup_{kind}_vs_cuthbertlib"] = run[f"jbevo_sqrt_{kind}"] / run[f"cuthbertlib_{kind}"]
            run[f"smoother_speedup_{kind}_vs_cuthbertlib"] = run[f"jbevo_smoother_{kind}"] / run[f"cuthbertlib_uks_{kind}"]
        run["batch_last_speedup_vs_vmap"] = run["jbevo_batch_last64"] / run["jbevo_vmap64"]
        run["speedup_batch_last64_vs_dynamax"] = run["jbevo_batch_last64"] / run["dynamax_vmap64"]
        run["smoother_speedup_batch_last64_vs_dynamax"] = run["jbevo_smoother_batch_last64"] / run["dynamax_uks_vmap64"]
        run["grad_batch_last_speedup_vs_vmap"] = run["jbevo_grad_batch_last64"] / run["jbevo_grad_vmap64"]
        run["tria_speedup_vs_lapack_qr"] = run["jbevo_sqrt_single"] / run["jbevo_sqrt_single_lapack_qr"]
        run["speedup_single_vs_dynamax_blocked"] = run["jbevo_single_blocked"] / run["dynamax_single"]
        run["smoother_speedup_single_vs_dynamax_blocked"] = run["jbevo_smoother_single_blocked"] / run["dynamax_uks_single"]
        for kind in ("single", "sqrt_single", "smoother_single", "vmap64", "grad_single"):
            run[f"blocked_speedup_{kind}"] = run[f"jbevo_{kind}_blocked"] / run[f"jbevo_{kind}"]
            run[f"one_kernel_speedup_{kind}"] = run[f"jbevo_{kind}"] / run[f"jbevo_{kind}_plain_loop"]
        runs.append(run)
    results["runs"] = runs
    results |= results_compile
    results.update({name: float(np.median([r[name] for r in runs])) for name in runs[0]})

    fp_steps = args.filterpy_steps or steps
    t0 = time.perf_counter()
    fp_means = run_filterpy(np.asarray(x0[0]), np.asarray(one.increments[:fp_steps]), np.asarray(one.fixes[:fp_steps]))
    results["filterpy_single"] = fp_steps / (time.perf_counter() - t0)

    jb_means, _ = jb_single(x0[0], one.increments, one.fixes)
    diff = np.asarray(jb_means[:fp_steps]) - fp_means
    diff[:, 2] = np.asarray(wrap_angle(diff[:, 2]))
    results["max_abs_diff_vs_filterpy"] = float(np.abs(diff).max())
    dyn_means, _ = dyn_single(pred0.mean[0], pred0.cov[0], dyn_inputs[0], fixes_unwrapped[0])
    diff = np.asarray(jb_means) - np.asarray(dyn_means)
    diff[:, 2] = np.asarray(wrap_angle(diff[:, 2]))
    results["max_abs_diff_vs_dynamax"] = float(np.abs(diff).max())
    sqrt_means, sqrt_chol = sqrt_single(x0[0], one.increments, one.fixes)
    _, jb_covs = jb_single(x0[0], one.increments, one.fixes)
    results["max_abs_diff_sqrt_vs_covariance_form"] = float(
        max(np.abs(np.asarray(sqrt_means - jb_means)).max(), np.abs(np.asarray(sqrt_chol @ sqrt_chol.mT - jb_covs)).max())
    )
    sm_means, sm_covs = smooth_single(x0[0], one.increments, one.fixes)
    uks_means, _ = uks_single(pred0.mean[0], pred0.cov[0], dyn_inputs[0], fixes_unwrapped[0])
    diff = np.asarray(sm_means) - np.asarray(uks_means)
    diff[:, 2] = np.asarray(wrap_angle(diff[:, 2]))
    results["max_abs_diff_smoother_vs_dynamax_uks"] = float(np.abs(diff).max())
    for name, run_peer, ours in (("", cb_single, (jb_means, jb_covs)), ("smoother_", cb_uks_single, (sm_means, sm_covs))):
        peer_means, peer_chol = run_peer(x0[0], one.increments, fixes_unwrapped[0])
        diff = np.asarray(ours[0]) - np.asarray(peer_means)
        diff[:, 2] = np.asarray(wrap_angle(diff[:, 2]))
        results[f"max_abs_diff_{name}vs_cuthbertlib"] = float(
            max(np.abs(diff).max(), np.abs(np.asarray(peer_chol @ peer_chol.mT - ours[1])).max())
        )

    results["max_abs_diff_blocked_vs_plain"] = float(
        max(
            np.abs(np.asarray(a) - np.asarray(b)).max()
            for name, plain in (("jbevo_single_blocked", jb_single), ("jbevo_smoother_single_blocked", smooth_single))
            for a, b in zip(blocked[name](x0[0], one.increments, one.fixes), plain(x0[0], one.increments, one.fixes), strict=True)
        )
    )
    results["max_abs_diff_one_kernel_vs_plain_loop"] = float(
        max(
            np.abs(np.asarray(a) - np.asarray(b)).max()
            for ours, plain in ((jb_single, "jbevo_single_plain_loop"), (smooth_single, "jbevo_smoother_single_plain_loop"))
            for a, b in zip(ours(*single_args), plain_loops[plain](*single_args), strict=True)
        )
    )
    results["max_abs_diff_batch_last_vs_vmap"] = float(
        max(
            np.abs(np.asarray(jnp.moveaxis(a, -1, 0)) - np.asarray(b)).max()
            for ours, theirs in (("jbevo_batch_last64", jb_batch), ("jbevo_smoother_batch_last64", smooth_batch))
            for a, b in zip(batch_last[ours](*trailing), theirs(*leading), strict=True)
        )
    )
    g_last, g_vmap = batch_last["jbevo_grad_batch_last64"](*trailing), grad_batch(*leading)
    results["max_rel_diff_grad_batch_last_vs_vmap"] = float(
        np.abs(np.asarray(jnp.moveaxis(g_last, -1, 0)) - np.asarray(g_vmap)).max() / np.abs(np.asarray(g_vmap)).max()
    )
    results["speedup_single_vs_filterpy"] = results["jbevo_single"] / results["filterpy_single"]
    results["machine"] = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}"
    print_table(results)
    write_json_atomic(args.out, results)
    return results


def make_dynamax_runner(trig=lambda a: (jnp.sin(a), jnp.cos(a)), smoothed: bool = False):
    """dynamax's UKF (or, ``smoothed``, its unscented Kalman smoother) on the localization
    model; ``trig`` gives the motion model's (sin, cos)."""
    from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM, UKFHyperParams, unscented_kalman_filter, unscented_kalman_smoother

    hyper = UKFHyperParams(alpha=ALPHA, beta=BETA, kappa=KAPPA)

    def motion(x, u):  # dynamax averages angles linearly: it runs on unwrapped yaw
        s, c = trig(x[2])
        return jnp.stack([x[0] + c * u[0] - s * u[1], x[1] + s * u[0] + c * u[1], x[2] + u[2]])

    def run(mean0, cov0, inputs, fixes):
        params = ParamsNLGSSM(
            initial_mean=mean0,
            initial_covariance=cov0,
            dynamics_function=motion,
            dynamics_covariance=jnp.asarray(Q),
            emission_function=lambda x, u: x,
            emission_covariance=jnp.asarray(R),
        )
        if smoothed:
            post = unscented_kalman_smoother(params, fixes, hyper, inputs=inputs)
            return post.smoothed_means, post.smoothed_covariances
        post = unscented_kalman_filter(
            params, fixes, hyper, inputs=inputs, output_fields=["filtered_means", "filtered_covariances"]
        )
        return post.filtered_means, post.filtered_covariances

    return run


def print_table(r: dict) -> None:
    print(f"UKF, localization model, T = {r['T']}, {r['dtype']}, {r['machine']}")
    print(
        "each loop one XLA:CPU kernel against plain loops: "
        + ", ".join(
            f"{kind} {r[f'one_kernel_speedup_{kind}']:.2f}x"
            for kind in ("single", "sqrt_single", "smoother_single", "vmap64", "grad_single")
        )
        + f"; max |difference| {r['max_abs_diff_one_kernel_vs_plain_loop']:.1e}"
    )
    print(
        'block="auto" against one lax.scan: '
        + ", ".join(
            f"{kind} {r[f'blocked_speedup_{kind}']:.2f}x"
            for kind in ("single", "sqrt_single", "smoother_single", "vmap64", "grad_single")
        )
        + f"; blocked filter {r['speedup_single_vs_dynamax_blocked']:.2f}x dynamax, blocked filter + smoother "
        f"{r['smoother_speedup_single_vs_dynamax_blocked']:.2f}x dynamax UKS; max |blocked - plain| "
        f"{r['max_abs_diff_blocked_vs_plain']:.1e}; compile (s) "
        + ", ".join(f"{k[10:]} {v:.2f}" for k, v in r.items() if k.startswith("compile_s_"))
    )
    print(f"{'method':<10} {'single (steps/s)':>18} {'vmap x' + str(r['batch']) + ' (steps/s)':>22}")
    print(f"{'jbevo':<10} {r['jbevo_single']:>18,.0f} {r['jbevo_vmap64']:>22,.0f}")
    print(f"{'dynamax':<10} {r['dynamax_single']:>18,.0f} {r['dynamax_vmap64']:>22,.0f}")
    print(f"{'dynamax*':<10} {'-':>18} {r['dynamax_vmap64_sincos']:>22,.0f}")
    print(f"{'filterpy':<10} {r['filterpy_single']:>18,.0f} {'-':>22}")
    print(f"{'jbevo, batch last':<10} {'-':>18} {r['jbevo_batch_last64']:>22,.0f}")
    print(
        f"jbevo/dynamax: single {r['speedup_single_vs_dynamax']:.2f}x, vmap {r['speedup_vmap64_vs_dynamax']:.2f}x; "
        f"jbevo/filterpy {r['speedup_single_vs_filterpy']:.0f}x; jbevo with input checks "
        f"{r['jbevo_single_checked']:,.0f} steps/s; vmap vs dynamax with jbevo's sincos "
        f"{r['speedup_vmap64_vs_dynamax_sincos']:.2f}x (dynamax* = dynamax given jbevo's sincos)"
    )
    print(
        f"max |jbevo - filterpy| = {r['max_abs_diff_vs_filterpy']:.2e}, "
        f"max |jbevo - dynamax| = {r['max_abs_diff_vs_dynamax']:.2e}"
    )
    print(
        f"square-root form: {r['jbevo_sqrt_single']:,.0f} / {r['jbevo_sqrt_vmap64']:,.0f} steps/s "
        f"(covariance form {r['sqrt_slowdown_single']:.2f}x / {r['sqrt_slowdown_vmap64']:.2f}x faster; "
        f"max |difference| {r['max_abs_diff_sqrt_vs_covariance_form']:.1e}); tria by MGS "
        f"{r['tria_speedup_vs_lapack_qr']:.2f}x faster than LAPACK's QR in the filter"
    )
    print(
        f"filter + RTS smoother: {r['jbevo_smoother_single']:,.0f} / {r['jbevo_smoother_vmap64']:,.0f} steps/s, "
        f"dynamax UKS {r['dynamax_uks_single']:,.0f} / {r['dynamax_uks_vmap64']:,.0f} "
        f"({r['smoother_speedup_single_vs_dynamax']:.2f}x / {r['smoother_speedup_vmap64_vs_dynamax']:.2f}x); "
        f"max |jbevo - dynamax| smoothed {r['max_abs_diff_smoother_vs_dynamax_uks']:.2e}"
    )
    print(
        f"cuthbertlib square-root UKF {r['cuthbertlib_single']:,.0f} / {r['cuthbertlib_vmap64']:,.0f} steps/s "
        f"(jbevo's square-root form {r['sqrt_speedup_single_vs_cuthbertlib']:.2f}x / {r['sqrt_speedup_vmap64_vs_cuthbertlib']:.2f}x), "
        f"with RTS {r['cuthbertlib_uks_single']:,.0f} / {r['cuthbertlib_uks_vmap64']:,.0f} (jbevo's smoother "
        f"{r['smoother_speedup_single_vs_cuthbertlib']:.2f}x / {r['smoother_speedup_vmap64_vs_cuthbertlib']:.2f}x); "
        f"max |difference| filter {r['max_abs_diff_vs_cuthbertlib']:.1e}, smoother {r['max_abs_diff_smoother_vs_cuthbertlib']:.1e}"
    )
    print(
        f"batch last (vmap_last) over {r['batch']}: filter {r['batch_last_speedup_vs_vmap']:.2f}x jax.vmap, "
        f"{r['speedup_batch_last64_vs_dynamax']:.2f}x dynamax vmapped; filter + smoother "
        f"{r['smoother_speedup_batch_last64_vs_dynamax']:.2f}x dynamax UKS vmapped; gradient "
        f"{r['grad_batch_last_speedup_vs_vmap']:.2f}x jax.vmap's; max |batch last - vmap| "
        f"{r['max_abs_diff_batch_last_vs_vmap']:.1e}, gradient {r['max_rel_diff_grad_batch_last_vs_vmap']:.1e} (relative)"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
