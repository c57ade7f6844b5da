"""Model checkpoints: the model's whole structure, its learnable leaves, the optimizer state and
the training progress in one file, written atomically.

A checkpoint is a ``.npz`` archive with ``config`` (JSON: the model's tree, every
``equinox.Module`` by its class and every field by its value, so static settings such as DPC's
radii or a BEV grid come back exactly), ``leaves`` (``equinox.tree_serialise_leaves`` of
``(model, opt_state)``) and ``progress`` (JSON). Only jbevo's own classes are rebuilt from a
file. A missing file raises ``FileNotFoundError``; a file that is not a checkpoint, or one whose
structure does not match the classes of this jbevo, raises ``ValueError`` naming the file and
what is wrong.
"""

from __future__ import annotations

import dataclasses
import importlib
import io
import json
import zipfile
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jbevo.files import write_atomic

FORMAT = 2


def describe(tree: Any) -> Any:
    """A JSON-able description of a model: modules by class and fields, arrays by shape and
    dtype (their values are saved apart), Python scalars, strings, None and tuples as they are."""
    if isinstance(tree, eqx.Module):
        cls = type(tree)
        fields = {f.name: describe(getattr(tree, f.name)) for f in dataclasses.fields(tree)}
        return {"module": f"{cls.__module__}:{cls.__qualname__}", "fields": fields}
    if isinstance(tree, (jax.Array, np.ndarray)):
        return {"array": list(tree.shape), "dtype": str(tree.dtype)}
    if tree is None or isinstance(tree, (bool, int, float, str)):
        return tree
    if isinstance(tree, tuple):
        return {"tuple": [describe(v) for v in tree]}
    raise ValueError(f"a checkpoint cannot record a {type(tree).__name__} ({tree!r})")


def rebuild(description: Any) -> Any:
    """The model :func:`describe` described, with zero arrays in place of the learned leaves."""
    if isinstance(description, dict):
        if "module" in description:
            cls = _module_class(description["module"])
            fields = {f.name: f for f in dataclasses.fields(cls)}
            got = set(description["fields"])
            # A field the class gained after the checkpoint was written takes its default.
            defaulted = {n for n, f in fields.items() if n not in got and f.default is not dataclasses.MISSING}
            if got | defaulted != set(fields):
                raise ValueError(f"{cls.__qualname__} has the fields {sorted(fields)}, the checkpoint {sorted(got)}")
            obj = object.__new__(cls)
            for name, value in description["fields"].items():
                object.__setattr__(obj, name, rebuild(value))
            for name in defaulted:
                object.__setattr__(obj, name, fields[name].default)
            return obj
        if "array" in description:
            return jnp.zeros(tuple(description["array"]), np.dtype(description["dtype"]))
        if "tuple" in description:
            return tuple(rebuild(v) for v in description["tuple"])
        raise ValueError(f"unknown entry {sorted(description)} in a checkpoint's model description")
    if isinstance(description, list):
        raise ValueError("unknown list in a checkpoint's model description")
    return description


def _module_class(name: str) -> type:
    module, _, qualname = name.partition(":")
    if module != "jbevo" and not module.startswith("jbevo."):
        raise ValueError(f"a checkpoint may only hold jbevo's classes, not {name}")
    try:
        obj: Any = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as error:
        raise ValueError(f"this jbevo has no class {name}") from error
    if not (isinstance(obj, type) and issubclass(obj, eqx.Module)):
        raise ValueError(f"{name} is not a model class")
    return obj


def model_config(model: eqx.Module) -> dict:
    """What rebuilds ``model``'s structure (not its learned values)."""
    return {"format": FORMAT, "model": describe(model)}


def model_from_config(config: dict) -> Any:
    """A model with the structure ``config`` describes and zero learnable leaves."""
    if config.get("format") != FORMAT:
        raise ValueError(f"checkpoint format {config.get('format')} is not {FORMAT}")
    return rebuild(config["model"])


def save(path: str | Path, model: eqx.Module, opt_state: Any = None, progress: dict | None = None) -> None:
    """Write ``model`` (its structure and leaves), ``opt_state`` and ``progress`` to ``path``
    atomically."""
    leaves = io.BytesIO()
    eqx.tree_serialise_leaves(leaves, (model, opt_state))
    buffer = io.BytesIO()
    np.savez(
        buffer,
        config=np.array(json.dumps(model_config(model))),
        leaves=np.frombuffer(leaves.getvalue(), np.uint8),
        progress=np.array(json.dumps(progress or {})),
    )
    write_atomic(Path(path), lambda f: f.write(buffer.getvalue()), mode="wb")


def load(path: str | Path, opt_state_like: Any = None) -> tuple[Any, Any, dict]:
    """``(model, opt_state, progress)`` from ``path``; ``opt_state_like`` is an optimizer state of
    the right structure (``optimizer.init(model params)``), or None to skip it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {path}")
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path} is not a readable jbevo checkpoint (not an .npz archive)")
    try:
        with np.load(path, allow_pickle=False) as data:
            config = json.loads(str(data["config"]))
            raw = data["leaves"].tobytes()
            progress = json.loads(str(data["progress"]))
    except (zipfile.BadZipFile, OSError, ValueError, KeyError, EOFError) as error:
        raise ValueError(f"{path} is not a readable jbevo checkpoint ({error})") from error
    try:
        model = model_from_config(config)
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{path} holds an incompatible model configuration ({error})") from error
    like = (model, opt_state_like)
    try:
        model, opt_state = eqx.tree_deserialise_leaves(io.BytesIO(raw), like)
    except Exception as error:  # equinox raises RuntimeError/ValueError/EOFError variously
        raise ValueError(f"{path} does not match the model and optimizer it should hold ({error})") from error
    return model, opt_state, progress


def load_model(path: str | Path, kind: type | None = None) -> Any:
    """The model of a checkpoint file, or of a training folder's ``best.ckpt``; with ``kind``, a
    ``ValueError`` unless it is one."""
    path = Path(path)
    path = path / "best.ckpt" if path.is_dir() else path
    model, _, _ = load(path)
    if kind is not None and not isinstance(model, kind):
        raise ValueError(f"{path} holds a {type(model).__name__}, not a {kind.__name__}")
    return model


__all__ = ["FORMAT", "describe", "load", "load_model", "model_config", "model_from_config", "rebuild", "save"]
