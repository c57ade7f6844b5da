"""Vision: the BEV projection of a camera image, differentiable phase correlation (DPC), the BEV
band geometry, the camera against the road (road view), and matching a BEV against a top-down map.

Example::

    from jbevo.geometry import BevGrid, Camera
    from jbevo.vision import bev_project, register

    bev_a, _ = bev_project(image_a, pitch_a, roll_a, Camera.kitti(), BevGrid(0.1, (256, 256), near=4.0))
    r = register(bev_a, bev_b)          # rotation (rad), translation (x, y) px, confidence
"""

from jbevo.vision.bands import BandGeometry, BandShifts, register_bands
from jbevo.vision.bev import bev_increment, bev_project, feather_to_mean, feathered_bev
from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.map_matching import MapMatch, map_crop, match_to_map
from jbevo.vision.registration import Registration, register, register_translation
from jbevo.vision.road_view import RoadView

__all__ = [
    "BandGeometry",
    "BandShifts",
    "DPCParams",
    "MapMatch",
    "Registration",
    "RoadView",
    "bev_increment",
    "bev_project",
    "feather_to_mean",
    "feathered_bev",
    "map_crop",
    "match_to_map",
    "register",
    "register_bands",
    "register_translation",
]
