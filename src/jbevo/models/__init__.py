"""Models: BEVO (5-DoF visual-inertial odometry from BEVs) and BEVO+ (map localization), their
losses, jitted runs and hand-set presets.

Example::

    from jbevo.models import Bevo, run_bevo

    out = run_bevo(Bevo.create(), seq)      # increments, pitch_roll, confidence, poses
"""

from jbevo.models.baselines import map_matching_alone
from jbevo.models.bevo import Bevo, BevoOutput
from jbevo.models.bevo_plus import BevoPlus, LocalizationOutput
from jbevo.models.forward_fusion import ForwardFusion
from jbevo.models.losses import localization_loss, motion_loss, planar_huber, relative_motion
from jbevo.models.parameters import num_learnable
from jbevo.models.presets import localization_model, street_model
from jbevo.models.road_tilt import RoadTilt
from jbevo.models.runners import run_bevo, run_bevo_batch, run_bevo_plus, run_bevo_plus_batch
from jbevo.models.yaw_fusion import YawFusion

__all__ = [
    "Bevo",
    "BevoOutput",
    "BevoPlus",
    "ForwardFusion",
    "LocalizationOutput",
    "RoadTilt",
    "YawFusion",
    "localization_loss",
    "localization_model",
    "map_matching_alone",
    "motion_loss",
    "num_learnable",
    "planar_huber",
    "relative_motion",
    "run_bevo",
    "run_bevo_batch",
    "run_bevo_plus",
    "run_bevo_plus_batch",
    "street_model",
]
