"""jbevo: differentiable filtering and bird's-eye-view (BEV) visual-inertial odometry and map
localization in JAX, after BEVO.

Layers (imports flow one way)::

    filtering, geometry  <-  vision, inertial  <-  models  <-  training, eval  <-  cli
    data (Sequence, Map, readers; the synthetic world in data.synthetic)

Example::

    import jbevo
    from jbevo.data.synthetic import procedural_sequence

    seq = procedural_sequence(seed=0, frames=120)
    out = jbevo.run_bevo(jbevo.Bevo.create(), seq)
"""

from jbevo import data, eval, filtering, geometry, inertial, models, training, vision
from jbevo.data import Map, Sequence
from jbevo.filtering import ukf, unscented
from jbevo.geometry import BevGrid, Camera
from jbevo.models import (
    Bevo,
    BevoOutput,
    BevoPlus,
    LocalizationOutput,
    run_bevo,
    run_bevo_batch,
    run_bevo_plus,
    run_bevo_plus_batch,
)
from jbevo.vision import DPCParams, register

__version__ = "0.1.0"

__all__ = [
    "BevGrid",
    "Bevo",
    "BevoOutput",
    "BevoPlus",
    "Camera",
    "DPCParams",
    "LocalizationOutput",
    "Map",
    "Sequence",
    "data",
    "eval",
    "filtering",
    "geometry",
    "inertial",
    "models",
    "register",
    "run_bevo",
    "run_bevo_batch",
    "run_bevo_plus",
    "run_bevo_plus_batch",
    "training",
    "ukf",
    "unscented",
    "vision",
]
