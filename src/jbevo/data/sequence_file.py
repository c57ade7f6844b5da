"""A :class:`~jbevo.data.sequence.Sequence` in one compressed ``.npz`` file (atomic writes; clear
errors for missing, truncated or inconsistent files)."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import Any

import jax.numpy as jnp
import numpy as np

from jbevo.data.sequence import Sequence, check
from jbevo.files import write_atomic
from jbevo.geometry.camera import Camera

_FIELDS = ("images", "frame_times", "imu_times", "gyro", "accel", "poses")


def save(seq: Sequence, path: str | Path) -> None:
    """Write an (unbatched) sequence to one ``.npz`` file, atomically."""
    if seq.frame_times.ndim != 1:
        raise ValueError(f"save writes one sequence; got a batch of shape {seq.frame_times.shape[:-1]}")
    check(seq)
    k = np.asarray(seq.camera.intrinsics)
    arrays: dict[str, Any] = {name: np.asarray(getattr(seq, name)) for name in _FIELDS}
    arrays |= {
        "intrinsics": k,
        "camera_height": np.asarray(seq.camera.height),
        "rotation_body_to_camera": np.asarray(seq.camera.rotation_body_to_camera),
    }
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    write_atomic(Path(path), lambda f: f.write(buffer.getvalue()), mode="wb")


def load(path: str | Path) -> Sequence:
    """Read a sequence written by :func:`save`; ``ValueError`` for a missing, truncated or
    inconsistent file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no sequence file at {path}")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in (*_FIELDS, "intrinsics", "camera_height", "rotation_body_to_camera")}
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as error:
        raise ValueError(f"{path} is not a readable sequence file ({error})") from error
    except KeyError as error:
        raise ValueError(f"{path} lacks the array {error} of a sequence file") from error
    k = arrays["intrinsics"]
    if k.shape != (3, 3) or arrays["images"].ndim != 3:
        raise ValueError(f"{path}: intrinsics {k.shape} / images {arrays['images'].shape} are not one sequence's")
    camera = Camera(
        k[0, 0],
        k[1, 1],
        k[0, 2],
        k[1, 2],
        arrays["images"].shape[-2:],
        float(arrays["camera_height"]),
        arrays["rotation_body_to_camera"],
    )
    seq = Sequence(camera=camera, **{name: jnp.asarray(arrays[name]) for name in _FIELDS})
    return check(seq)


__all__ = ["load", "save"]
