"""Independent references the filtering tests compare with: filterpy's UKF on the planar
localization model (yaw wrapped as jbevo's model wraps it)."""

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

Q = np.diag([0.02, 0.01, 0.005]) ** 2
R = np.diag([0.5, 0.5, 0.05]) ** 2
P0 = np.diag([1.0, 1.0, 0.1]) ** 2


def wrap_np(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def filterpy_localization_filter(x0, alpha=1.0, beta=2.0, kappa=0.0):
    """filterpy 2.0's UKF on the localization model (``fx(x, dt, u)``: ``u`` the odometry
    increment), with matching angle functions, at ``x0`` and :data:`P0`."""

    def residual(a, b):
        d = np.subtract(a, b)
        d[2] = wrap_np(d[2])
        return d

    def add(x, dx):
        s = np.add(x, dx)
        s[2] = wrap_np(s[2])
        return s

    def mean(points, w):
        m = w @ points
        ref = points[0, 2]
        m[2] = wrap_np(ref + w @ wrap_np(points[:, 2] - ref))
        return m

    def fx(x, dt, u):
        c, s = np.cos(x[2]), np.sin(x[2])
        return np.array([x[0] + c * u[0] - s * u[1], x[1] + s * u[0] + c * u[1], wrap_np(x[2] + u[2])])

    points = MerweScaledSigmaPoints(3, alpha, beta, kappa, subtract=residual)
    f = UnscentedKalmanFilter(
        3,
        3,
        1.0,
        lambda x: x,
        fx,
        points,
        x_mean_fn=mean,
        z_mean_fn=mean,
        residual_x=residual,
        residual_z=residual,
        state_add=add,
    )
    f.x, f.P, f.Q, f.R = np.array(x0, float), P0.copy(), Q.copy(), R.copy()
    return f, fx


def filterpy_localization(x0, increments, fixes, alpha=1.0, beta=2.0, kappa=0.0):
    """filterpy's UKF run over the increments and fixes (a fix of None: no update): per step the
    predicted and filtered moments and the log-likelihood; ``"filter"`` is the filter object."""
    f, _ = filterpy_localization_filter(x0, alpha, beta, kappa)
    out = {"mean": [], "cov": [], "pred_mean": [], "pred_cov": [], "ll": []}
    for u, z in zip(increments, fixes):
        f.predict(u=u)
        out["pred_mean"].append(f.x.copy())
        out["pred_cov"].append(f.P.copy())
        f.update(None if z is None or np.any(np.isnan(z)) else z)
        out["mean"].append(f.x.copy())
        out["cov"].append(f.P.copy())
        out["ll"].append(f.log_likelihood)
    return {k: np.array(v) for k, v in out.items()} | {"filter": f}
