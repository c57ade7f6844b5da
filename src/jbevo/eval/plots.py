"""Trajectory and error figures (matplotlib's object-oriented API, no pyplot: importing this module
changes no global backend), written atomically as PNG.

* :func:`trajectory_top_view`: ground truth and one or more estimates seen from above.
* :func:`segment_errors`: KITTI translation and rotation error per segment length, per method.
* :func:`error_over_time`: any per-frame error curves (position error, yaw error, ...).

Each returns the ``matplotlib.figure.Figure`` (for notebooks) after saving it to ``path``.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from jbevo.files import write_atomic

_AXIS = "xyz"


def _figure(size: tuple[float, float], columns: int = 1) -> tuple[Figure, list]:
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    return fig, [fig.add_subplot(1, columns, i + 1) for i in range(columns)]


def _save(fig: Figure, path: str | Path | None) -> Figure:
    if path is not None:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=120, bbox_inches="tight")
        write_atomic(Path(path), lambda f: f.write(buf.getvalue()), mode="wb")
    return fig


def _positions(traj) -> np.ndarray:
    traj = np.asarray(traj)
    if traj.ndim == 3:
        return traj[:, :3, 3]
    if traj.ndim == 2 and traj.shape[1] == 3:  # planar (x, y, yaw)
        return np.concatenate([traj[:, :2], np.zeros((len(traj), 1))], axis=1)
    raise ValueError(f"a trajectory must be (N, 4, 4) poses or (N, 3) planar rows, got {traj.shape}")


def trajectory_top_view(
    path: str | Path | None,
    gt,
    estimates: Mapping[str, object],
    plane: tuple[int, int] = (0, 1),
    title: str | None = None,
    legend_below: bool = False,
):
    """Top view of ``gt`` and each named estimate on the axes ``plane`` (``(0, 2)``: KITTI camera
    x and z; ``(0, 1)``: a z-up world or planar trajectories). The start is marked. With
    ``legend_below`` the legend sits under the axes, clear of every curve."""
    fig, (ax,) = _figure((6, 6))
    g = _positions(gt)
    ax.plot(g[:, plane[0]], g[:, plane[1]], "k-", lw=2, label="ground truth")
    for name, est in estimates.items():
        e = _positions(est)
        ax.plot(e[:, plane[0]], e[:, plane[1]], lw=1.2, label=name)
    ax.plot(g[0, plane[0]], g[0, plane[1]], "ko", ms=6, label="start")
    ax.set_xlabel(f"{_AXIS[plane[0]]} [m]")
    ax.set_ylabel(f"{_AXIS[plane[1]]} [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    if legend_below:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8, frameon=False)
    else:
        ax.legend()
    if title:
        ax.set_title(title)
    return _save(fig, path)


def segment_errors(
    path: str | Path | None,
    lengths: Sequence[float],
    t_err_pct: Mapping[str, Sequence[float]],
    r_err_deg_per_100m: Mapping[str, Sequence[float]],
):
    """KITTI errors per segment length: translation (%) and rotation (deg / 100 m), per method."""
    fig, (at, ar) = _figure((10, 4), 2)
    for name, values in t_err_pct.items():
        at.plot(lengths, values, "o-", label=name)
    for name, values in r_err_deg_per_100m.items():
        ar.plot(lengths, values, "o-", label=name)
    at.set_ylabel("translation error [%]")
    ar.set_ylabel("rotation error [deg / 100 m]")
    for ax in (at, ar):
        ax.set_xlabel("segment length [m]")
        ax.grid(alpha=0.3)
        ax.legend()
    return _save(fig, path)


def error_over_time(path: str | Path | None, time_s, errors: Mapping[str, object], ylabel: str = "error"):
    """Per-frame error curves against time (or frame index)."""
    fig, (ax,) = _figure((8, 3.5))
    for name, values in errors.items():
        ax.plot(np.asarray(time_s), np.asarray(values), lw=1, label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, path)


__all__ = ["error_over_time", "segment_errors", "trajectory_top_view"]
