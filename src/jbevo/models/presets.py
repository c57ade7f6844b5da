"""Hand-set models for the scenes jbevo ships (:mod:`jbevo.data.synthetic.scenes`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from jbevo.data.synthetic.scenes import SCENE_KINDS
from jbevo.geometry.bev_grid import BevGrid
from jbevo.models.bevo import Bevo
from jbevo.models.bevo_plus import BevoPlus
from jbevo.models.road_tilt import RoadTilt
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


#: The pitch and roll rate (rad/s) the real-street model's attitude filter assumes through a frame
#: whose gyro block is missing (:attr:`jbevo.inertial.speed_aided.SpeedAidedAttitude.gap_rate_std`):
#: 1.5 deg/s, the RMS of the roll and pitch rates of KITTI's training drives on record (00, 01,
#: 02, 04, 05, 08; ``benchmarks/real_kitti.py`` writes it as ``training_tilt_rate_rms_deg_s``).
STREET_GAP_RATE_STD = float(np.radians(1.5))


#: The walk of the level road's tilt (radians per square-root metre: 0.2 deg over a kilometre),
#: chosen on the street world's KITTI 00 and 08 (800 frames each, seed 100; no test drive) among
#: 0.0025 (the grade's walk), 0.001, 0.0005, 0.00025, 0.0001 and 0.00005: the pooled t_err fell
#: with the walk and had flattened by 0.0001 (4.8 %, 4.7 % at 0.00005; a probe, not a record).
LEVEL_ROAD_WALK = 1e-4


def street_model(
    imu_dt: float,
    grid: BevGrid = STREET_GRID,
    bands: bool = True,
    bands_min_travel: float = STREET_BANDS_MIN_TRAVEL,
    bands_keyframes: bool = False,
    forward_fusion: bool = False,
    level_road: bool = False,
) -> Bevo:
    """The hand-set BEVO for real streets (KITTI-size frames with a calibrated IMU): the road view
    (:class:`jbevo.vision.road_view.RoadView`: camera against the road, road corridor), the gyro's
    turn fused with DPC's (:class:`jbevo.models.yaw_fusion.YawFusion`), DPC's rotation searched
    within :data:`STREET_GYRO_WINDOW` of the gyro's, the attitude uncertain by
    :data:`STREET_GAP_RATE_STD` through missing gyro blocks, and with ``bands`` the robust band update,
    engaged from ``bands_min_travel`` metres per frame, measuring the road's tilt
    (:class:`jbevo.models.road_tilt.RoadTilt`) rather than the pitch against gravity; with
    ``bands_keyframes`` the bands hold keyframes below that travel
    (:attr:`jbevo.vision.bands.BandGeometry.keyframes`; off: worse on the real KITTI 07 run,
    ``benchmarks/real_kitti.py``); with ``forward_fusion`` the forward motion per frame fuses the
    accelerometer's speed with DPC's increment (:class:`jbevo.models.forward_fusion.ForwardFusion`;
    off by default: ``benchmarks/forward_fusion.py``); with ``level_road`` (and ``bands``) the BEV
    is projected on the road's plane, its pitch the tilt state alone, walking by
    :data:`LEVEL_ROAD_WALK` (:attr:`jbevo.models.road_tilt.RoadTilt.level`; off by default: worse
    than without it on the real KITTI runs and on the street world's KITTI 09 and 10,
    ``benchmarks/real_kitti.py``, ``benchmarks/street_oracle.py``)."""
    model = Bevo.create(
        grid, imu_dt, gyro_window=STREET_GYRO_WINDOW, road=True, yaw_fusion=True, road_tilt=bands, forward_fusion=forward_fusion
    )
    model = dataclasses.replace(model, attitude=dataclasses.replace(model.attitude, gap_rate_std=STREET_GAP_RATE_STD))
    geometry = BandGeometry.create(robust=True, min_travel=bands_min_travel, keyframes=bands_keyframes) if bands else None
    if level_road:
        if not bands:
            raise ValueError("level_road needs bands: they are what measures the camera's pitch against the road")
        model = dataclasses.replace(model, road_tilt=RoadTilt.create(LEVEL_ROAD_WALK, level=True))
    return dataclasses.replace(model, bands=geometry)


__all__ = [
    "GYRO_WINDOW",
    "LEVEL_ROAD_WALK",
    "STREET_BANDS_MIN_TRAVEL",
    "STREET_GAP_RATE_STD",
    "STREET_GRID",
    "STREET_GYRO_WINDOW",
    "localization_model",
    "street_model",
]
