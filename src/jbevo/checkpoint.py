"""BEVO and BEVO+ checkpoints: the model's configuration, its learnable leaves, the optimizer state and the
training progress in one file, written atomically.

A checkpoint is a ``.npz`` archive with ``config`` (JSON: what is needed to rebuild the model's
structure), ``leaves`` (``equinox.tree_serialise_leaves`` of ``(model, opt_state)``) and
``progress`` (JSON). Loading rebuilds the model from the config and reads the leaves into it; a
missing file, a file that is not a checkpoint, or one whose structure does not match raises a
``ValueError`` (``FileNotFoundError``) naming the file and what is wrong.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

import equinox as eqx
import numpy as np

from jbevo.camera import BevGrid
from jbevo.files import write_atomic
from jbevo.localization import BevoPlus
from jbevo.odometry import Bevo

FORMAT = 1


def _grid_config(g: BevGrid) -> dict:
    return {"resolution": g.resolution, "shape": list(g.shape), "origin": list(g.origin)}


def _grid(g: dict) -> BevGrid:
    return BevGrid(g["resolution"], tuple(g["shape"]), tuple(g["origin"]))


def model_config(model: Bevo | BevoPlus) -> dict:
    """What rebuilds ``model``'s structure (not its learned values): a BEVO odometry model or a
    BEVO+ localizer (``"kind"``)."""
    if isinstance(model, BevoPlus):
        return {
            "format": FORMAT, "kind": "bevo+", "odometry": model_config(model.odometry),
            "map_grid": _grid_config(model.map_grid), "map_n_angles": model.map_dpc.n_angles,
            "min_confidence": model.min_confidence, "gate": model.gate, "gyro_yaw": model.gyro_yaw,
            "reacquire_after": model.reacquire_after,
        }
    return {
        "format": FORMAT,
        "kind": "bevo",
        "grid": _grid_config(model.grid),
        "imu_dt": model.attitude.dt,
        "n_angles": model.dpc.n_angles,
        "attitude_source": model.attitude_source,
        "gyro_window": model.gyro_window,
        "bands": model.bands is not None,
    }


def model_from_config(config: dict) -> Bevo | BevoPlus:
    """A hand-set model with the structure ``config`` describes."""
    if config.get("format") != FORMAT:
        raise ValueError(f"checkpoint format {config.get('format')} is not {FORMAT}")
    if config.get("kind", "bevo") == "bevo+":
        return BevoPlus.create(
            model_from_config(config["odometry"]), _grid(config["map_grid"]), min_confidence=config["min_confidence"],
            gate=config["gate"], gyro_yaw=config["gyro_yaw"], reacquire_after=config.get("reacquire_after", 5),
            n_angles=config["map_n_angles"],
        )
    return Bevo.create(
        _grid(config["grid"]), config["imu_dt"], config["attitude_source"], config.get("gyro_window", 0.0),
        bands=config.get("bands", False), n_angles=config["n_angles"],
    )


def save(path: str | Path, model: Bevo | BevoPlus, opt_state: Any = None, progress: dict | None = None) -> None:
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


def load(path: str | Path, opt_state_like: Any = None) -> tuple[Bevo | BevoPlus, Any, dict]:
    """``(model, opt_state, progress)`` from ``path``; ``opt_state_like`` is an optimizer state of
    the right structure (``optimizer.init(model params)``), or None to skip it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {path}")
    try:
        with np.load(path) as data:
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
