"""Hand-set models for the scenes jbevo ships (:mod:`jbevo.data.synthetic.scenes`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from jbevo.data.synthetic.scenes import SCENE_KINDS
from jbevo.geometry.bev_grid import BevGrid
from jbevo.models.bevo import Bevo
from jbevo.models.bevo_plus import BevoPlus
from jbevo.vision.bands import BandGeometry

#: BEVO+'s odometry searches DPC's rotation within this many radians of the gyro's turn.
GYRO_WINDOW = float(np.radians(2.0))


def localization_model(kind: str, street: bool = False) -> BevoPlus:
    """The hand-set BEVO+ for a scene kind (``carla`` or ``aeroground``): its BEV grids, and the
    odometry's rotation searched within :data:`GYRO_WINDOW` of the gyro's turn. With ``street`` the
    odometry gains the street preset's parts (:func:`street_model`, without its bands): the road
    view, whose camera attitude and height the map match uses too, and the gyro's turn fused with
    DPC's."""
    if kind not in SCENE_KINDS:
        raise ValueError(f"unknown scene kind {kind!r}; known: {sorted(SCENE_KINDS)}")
    odometry_grid, map_grid = SCENE_KINDS[kind].grids()
    odometry = Bevo.create(odometry_grid, gyro_window=GYRO_WINDOW, road=street, yaw_fusion=street)
    return BevoPlus.create(odometry, map_grid)


#: The KITTI-size BEV of the real-street model: 256 x 256 at 0.1 m/px from 4 m ahead.
STREET_GRID = BevGrid(0.1, (256, 256), near=4.0)
#: The real-street model searches DPC's rotation within this many radians of the gyro's turn.
STREET_GYRO_WINDOW = float(np.radians(0.5))


#: Metres per frame below which the real-street model's bands stand aside: the slope's pitch
#: signal ``2 D e / h`` for e = 0.1 deg reaches its hand-set noise (0.003) at D ~ 1.4 m.
STREET_BANDS_MIN_TRAVEL = 1.0


def street_model(
    imu_dt: float,
    grid: BevGrid = STREET_GRID,
    bands: bool = True,
    bands_min_travel: float = STREET_BANDS_MIN_TRAVEL,
    bands_keyframes: bool = False,
    forward_fusion: bool = False,
) -> Bevo:
    """The hand-set BEVO for real streets (KITTI-size frames with a calibrated IMU): the road view
    (:class:`jbevo.vision.road_view.RoadView`: camera against the road, road corridor), the gyro's
    turn fused with DPC's (:class:`jbevo.models.yaw_fusion.YawFusion`), DPC's rotation searched
    within :data:`STREET_GYRO_WINDOW` of the gyro's, and with ``bands`` the robust band update,
    engaged from ``bands_min_travel`` metres per frame, measuring the road's tilt
    (:class:`jbevo.models.road_tilt.RoadTilt`) rather than the pitch against gravity; with
    ``bands_keyframes`` the bands hold keyframes below that travel
    (:attr:`jbevo.vision.bands.BandGeometry.keyframes`; off: worse on the real KITTI 07 run,
    ``benchmarks/real_kitti.py``); with ``forward_fusion`` the forward motion per frame fuses the
    accelerometer's speed with DPC's increment (:class:`jbevo.models.forward_fusion.ForwardFusion`;
    off by default: ``benchmarks/forward_fusion.py``)."""
    model = Bevo.create(
        grid, imu_dt, gyro_window=STREET_GYRO_WINDOW, road=True, yaw_fusion=True, road_tilt=bands, forward_fusion=forward_fusion
    )
    geometry = BandGeometry.create(robust=True, min_travel=bands_min_travel, keyframes=bands_keyframes) if bands else None
    return dataclasses.replace(model, bands=geometry)


__all__ = ["GYRO_WINDOW", "STREET_BANDS_MIN_TRAVEL", "STREET_GRID", "STREET_GYRO_WINDOW", "localization_model", "street_model"]
