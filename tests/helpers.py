"""Shared test helper: ``jax.grad`` of a model's loss against central finite differences, leaf by
leaf and element by element."""

import jax
import jax.numpy as jnp


def check_leaf_gradients(value, grads, params, abs_tol: float, rel_tol: float = 0.03, eps: float = 1e-5, skip=()) -> int:
    """Assert that every element of every leaf of ``grads`` (the gradient of ``value`` at
    ``params``) is finite and matches ``(value(p + eps) - value(p - eps)) / (2 eps)`` within
    ``rel_tol`` relative plus ``abs_tol``; leaves that are (by identity) in ``skip`` are left out.
    Returns the number of elements checked."""
    leaves, treedef = jax.tree_util.tree_flatten(params)
    grad_leaves = jax.tree_util.tree_leaves(grads)
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in grad_leaves)
    skipped = {id(x) for x in skip}
    checked = 0
    for i, (leaf, g) in enumerate(zip(leaves, grad_leaves)):
        if id(leaf) in skipped:
            continue
        for j in range(leaf.size):

            def shifted(d, i=i, j=j, leaf=leaf):
                new = list(leaves)
                new[i] = leaf.reshape(-1).at[j].add(d).reshape(leaf.shape)
                return float(value(jax.tree_util.tree_unflatten(treedef, new)))

            fd = (shifted(eps) - shifted(-eps)) / (2 * eps)
            analytic = float(g.reshape(-1)[j])
            assert abs(fd - analytic) <= rel_tol * max(abs(fd), abs(analytic)) + abs_tol, (
                f"leaf {i}[{j}]: finite difference {fd}, grad {analytic}"
            )
            checked += 1
    return checked


def run_processes(module: str, argv: list[str], devices: tuple[int, ...] = (1, 1)) -> list:
    """``python -m module argv`` as processes of one job on localhost, one per entry of
    ``devices`` with that many CPU devices (a free port for the coordinator); their
    ``CompletedProcess`` results, each checked to have succeeded."""
    import os
    import socket
    import subprocess
    import sys

    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"} | {"JAX_PLATFORMS": "cpu"}
    job = ["--coordinator", f"localhost:{port}", "--num-processes", str(len(devices))]
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", module, *argv, *job, "--process-id", str(i)],
            env=env | {"XLA_FLAGS": f"--xla_force_host_platform_device_count={n}"},
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i, n in enumerate(devices)
    ]
    results = []
    for p in procs:
        out, err = p.communicate(timeout=900)
        results.append(subprocess.CompletedProcess(p.args, p.returncode, out, err))
    for r in results:
        assert r.returncode == 0, r.stderr[-3000:]
    return results
