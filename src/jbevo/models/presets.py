"""Hand-set models for the scenes jbevo ships (:mod:`jbevo.data.synthetic.scenes`)."""

from __future__ import annotations

import numpy as np

from jbevo.data.synthetic.scenes import SCENE_KINDS
from jbevo.models.bevo import Bevo
from jbevo.models.bevo_plus import BevoPlus

#: BEVO+'s odometry searches DPC's rotation within this many radians of the gyro's turn.
GYRO_WINDOW = float(np.radians(2.0))


def localization_model(kind: str) -> BevoPlus:
    """The hand-set BEVO+ for a scene kind (``carla`` or ``aeroground``): its BEV grids, and the
    odometry's rotation searched within :data:`GYRO_WINDOW` of the gyro's turn."""
    if kind not in SCENE_KINDS:
        raise ValueError(f"unknown scene kind {kind!r}; known: {sorted(SCENE_KINDS)}")
    odometry_grid, map_grid = SCENE_KINDS[kind].grids()
    return BevoPlus.create(Bevo.create(odometry_grid, gyro_window=GYRO_WINDOW), map_grid)


__all__ = ["GYRO_WINDOW", "localization_model"]
