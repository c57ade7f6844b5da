"""jbevo: differentiable filtering and BEV visual-inertial odometry in JAX."""

__version__ = "0.1.0"
