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
