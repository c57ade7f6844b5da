"""The optimisation loop that ``python -m jbevo.train`` and ``python -m jbevo.localize train``
share: the optimizer and progress (or a resumed run), a jitted Adam step over vmapped windows,
one shuffled epoch with a progress bar, and the best/last checkpoints.

A step whose gradient holds a NaN or infinity (a rare batch where a gross registration failure
meets a degenerate corner of the recursion, while the loss itself is finite) is skipped: the
parameters and Adam's moments stay as they were (``optax.apply_if_finite``), a warning names the
step, and ``progress["skipped_steps"]`` counts it. After :data:`MAX_SKIPPED_IN_A_ROW` such steps
in a row the update is applied, and the non-finite loss that follows ends the run as
:class:`TrainingDiverged`.

With a :class:`jbevo.training.data_parallel.DataParallel` the batch is split over its devices
(of every process), each process slicing only its devices' windows, and the parameters and
Adam's state are replicated; the models yielded are this process's copy."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import numpy as np
import optax
from tqdm import tqdm

from jbevo.training import checkpoint
from jbevo.training.data_parallel import DataParallel, local_copy
from jbevo.training.windows import Windows

#: Consecutive steps with a non-finite gradient that are skipped before the run gives up.
MAX_SKIPPED_IN_A_ROW = 3


def make_step(
    static: Any,
    optimizer: optax.GradientTransformation,
    loss: Callable[[Any, Any], jax.Array],
    parallel: DataParallel | None = None,
):
    """A jitted ``step(params, opt_state, batch) -> (params, opt_state, loss)`` for
    ``loss(model, batch)`` (a mean over the batch), the model being ``eqx.combine(params, static)``;
    with ``parallel`` (more than one device) the loss and gradient are computed per shard of the
    batch and averaged over the devices."""

    def per_batch(params, batch):
        return jax.value_and_grad(lambda p: loss(eqx.combine(p, static), batch))(params)

    value_and_grad = per_batch if parallel is None or parallel.size == 1 else parallel.mean_over_batch(per_batch)

    @eqx.filter_jit
    def step(params, opt_state, batch):
        value, grads = value_and_grad(params, batch)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, value

    return step


class TrainingDiverged(RuntimeError):
    """The loss became NaN or infinite."""


def skipped_steps(opt_state: Any) -> int:
    """How many steps ``opt_state`` (of :func:`start_run`'s optimizer) has skipped for a
    non-finite gradient; 0 for any other optimizer state."""
    return int(local_copy(getattr(opt_state, "total_notfinite", 0)))


def take_batch(windows: Windows | Any, idx: np.ndarray, parallel: DataParallel | None = None) -> Any:
    """Windows ``idx`` of ``windows`` (a :class:`Windows`, or any batched pytree) as one batch;
    with ``parallel``, a global batch split over its devices, this process slicing only the
    windows its devices hold."""
    size = len(idx)
    if parallel is not None:
        idx = idx[parallel.local_rows(size)]
    if isinstance(windows, Windows):
        chunk = windows.batch(idx)
    else:
        chunk = jax.tree_util.tree_map(lambda x: x[idx], windows)
    return chunk if parallel is None else parallel.put_batch(chunk, size)


def run_epoch(
    step,
    params,
    opt_state,
    windows: Windows | Any,
    batch: int,
    rng: np.random.Generator,
    label: str,
    parallel: DataParallel | None = None,
):
    """One pass over the ``windows`` (a :class:`Windows` or a batched pytree) in shuffled batches
    of ``batch`` (:func:`take_batch`): ``(params, opt_state, mean loss, steps)``. A non-finite
    loss, or a runtime check inside the model that meets a non-finite value, raises
    :class:`TrainingDiverged`; a step the optimizer skipped for a non-finite gradient is reported
    on stderr."""
    n = len(windows) if isinstance(windows, Windows) else jax.tree_util.tree_leaves(windows)[0].shape[0]
    order = rng.permutation(n)
    steps = max(1, n // batch)
    bar = tqdm(range(steps), desc=label, file=sys.stderr, leave=False, disable=None)
    losses = []
    before = skipped_steps(opt_state)
    for i in bar:
        idx = order[i * batch : (i + 1) * batch]
        chunk = take_batch(windows, idx, parallel)
        try:
            params, opt_state, loss = step(params, opt_state, chunk)
        except eqx.EquinoxRuntimeError as error:  # a check inside the model met a NaN state
            marker = "EquinoxRuntimeError: "
            lines = [line.split(marker, 1)[1] for line in str(error).splitlines() if marker in line]
            reason = lines[0] if lines else "a runtime check failed"
            raise TrainingDiverged(
                f"the model produced non-finite values at {label}, step {i} ({reason}); lower the learning rate"
            ) from None
        loss = float(local_copy(loss))
        if not np.isfinite(loss):
            raise TrainingDiverged(f"the loss became {loss} at {label}, step {i}; lower the learning rate")
        if (skipped := skipped_steps(opt_state)) > before:
            tqdm.write(f"{label}, step {i}: the gradient is not finite; the update was skipped", file=sys.stderr)
        before = skipped
        losses.append(loss)
        bar.set_postfix(loss=f"{np.mean(losses[-10:]):.5f}")
    return params, opt_state, float(np.mean(losses)), steps


def train_epochs(
    step,
    params,
    static,
    opt_state,
    windows: Windows | Any,
    batch: int,
    seed: int,
    progress: dict,
    epochs: int,
    parallel: DataParallel | None = None,
):
    """Run the epochs from ``progress["epoch"]`` up to ``epochs`` (:func:`run_epoch` each, the
    shuffling drawn from one generator seeded by ``seed`` plus the epoch started from: a resumed
    run shuffles its epochs differently from an uninterrupted one; every process draws the same),
    counting them in ``progress``; after each, yield ``(model, opt_state, mean loss)`` with the
    model rebuilt from ``static`` (this process's copy of the parameters and state, with
    ``parallel``: they are replicated over its devices for the steps)."""
    if parallel is not None:
        parallel.check_batch(batch)
        params, opt_state = parallel.replicate((params, opt_state))
    rng = np.random.default_rng(seed + progress["epoch"])
    for epoch in range(progress["epoch"], epochs):
        params, opt_state, mean_loss, steps = run_epoch(
            step, params, opt_state, windows, batch, rng, f"epoch {epoch + 1}/{epochs}", parallel
        )
        progress["epoch"], progress["step"] = epoch + 1, progress["step"] + steps
        progress["skipped_steps"] = skipped_steps(opt_state)
        yield eqx.combine(local_copy(params), static), local_copy(opt_state), mean_loss


def start_run(model, out, lr: float, clip: float, resume: bool, best_key: str):
    """The Adam optimizer (gradient clipped at global norm ``clip``; steps with a non-finite
    gradient skipped, see the module docstring) and its state for ``model``,
    and the progress record; with ``resume``, all three from ``out/last.ckpt`` (which must hold
    a model of ``model``'s type). Returns ``(model, params, static, optimizer, opt_state,
    progress)``; ``progress[best_key]`` holds the best validation criterion so far."""
    optimizer = optax.apply_if_finite(optax.chain(optax.clip_by_global_norm(clip), optax.adam(lr)), MAX_SKIPPED_IN_A_ROW)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    opt_state = optimizer.init(params)
    progress = {"epoch": 0, "step": 0, "skipped_steps": 0, best_key: None, "history": []}
    out.mkdir(parents=True, exist_ok=True)
    if resume:
        loaded, opt_state, progress = checkpoint.load(out / "last.ckpt", opt_state)
        if type(loaded) is not type(model):
            raise ValueError(f"{out / 'last.ckpt'} holds a {type(loaded).__name__}, not a {type(model).__name__}")
        model = loaded
        params, static = eqx.partition(model, eqx.is_inexact_array)
        print(f"resumed from {out / 'last.ckpt'} at epoch {progress['epoch']}")
    return model, params, static, optimizer, opt_state, progress


def save_epoch(out, model, opt_state, progress: dict, best_key: str, criterion: float) -> None:
    """``out/last.ckpt`` always, ``out/best.ckpt`` when ``criterion`` beats ``progress[best_key]``
    (lower is better; both atomic; ``progress["best_epoch"]`` records ``progress["epoch"]``, 0 for
    the starting parameters). Of several processes only the first writes; all update ``progress``."""
    write = jax.process_index() == 0
    if progress[best_key] is None or criterion < progress[best_key]:
        progress[best_key] = criterion
        progress["best_epoch"] = progress["epoch"]
        if write:
            checkpoint.save(out / "best.ckpt", model, opt_state, progress)
    if write:
        checkpoint.save(out / "last.ckpt", model, opt_state, progress)


def load_best(out):
    """The model of ``out/best.ckpt`` and the epoch it was saved at (0: the starting, hand-set
    parameters, which no epoch validated better than)."""
    model, _, progress = checkpoint.load(out / "best.ckpt")
    return model, progress.get("best_epoch", 0)


__all__ = [
    "MAX_SKIPPED_IN_A_ROW",
    "TrainingDiverged",
    "load_best",
    "make_step",
    "run_epoch",
    "save_epoch",
    "skipped_steps",
    "start_run",
    "take_batch",
    "train_epochs",
]
