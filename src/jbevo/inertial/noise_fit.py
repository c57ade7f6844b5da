"""An IMU's noise from its data: the overlapping Allan deviation, the standard noise model fitted
to it, and the white noise seen at standstill (numpy; runs once per sensor).

The model (IEEE Std 952): ``adev(tau)^2 = N^2 / tau + (0.664 B)^2 + K^2 tau / 3`` with ``N`` the
white-noise density (unit/s^0.5 for a rate: rad/s/sqrt(Hz)), ``B`` the bias instability and ``K``
the bias random walk (unit/s/sqrt(Hz)); the fit is non-negative least squares on ``adev^2``.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls


def allan_deviation(samples: np.ndarray, dt: float, taus: np.ndarray) -> np.ndarray:
    """Overlapping Allan deviation ``(len(taus), C)`` of ``samples`` ``(M, C)`` taken every ``dt``
    at averaging times ``taus`` (each rounded to a whole number of samples, at least one, at most
    a third of the record; NaN beyond)."""
    x = np.asarray(samples, float)
    if x.ndim != 2 or len(x) < 3:
        raise ValueError(f"samples must have shape (M >= 3, C), got {x.shape}")
    theta = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, 0) * dt])
    out = np.full((len(taus), x.shape[1]), np.nan)
    for i, tau in enumerate(taus):
        m = max(1, int(round(tau / dt)))
        if 3 * m > len(x):
            continue
        d = theta[2 * m :] - 2 * theta[m:-m] + theta[: -2 * m]
        out[i] = np.sqrt(np.mean(d**2, 0) / (2 * (m * dt) ** 2))
    return out


def fit_allan(taus: np.ndarray, adev: np.ndarray) -> dict[str, np.ndarray]:
    """``{"white": N, "bias_instability": B, "random_walk": K}`` (per column) of the noise model
    fitted to an Allan deviation (NaN rows ignored)."""
    taus = np.asarray(taus, float)
    out = {k: np.zeros(adev.shape[1]) for k in ("white", "bias_instability", "random_walk")}
    for c in range(adev.shape[1]):
        ok = np.isfinite(adev[:, c])
        t = taus[ok]
        # Relative weighting: every tau counts alike in log terms.
        w = 1.0 / adev[ok, c] ** 2
        a = np.stack([1.0 / t, np.ones_like(t), t / 3.0], -1) * w[:, None]
        x, _ = nnls(a, adev[ok, c] ** 2 * w)
        out["white"][c], out["bias_instability"][c], out["random_walk"][c] = np.sqrt(x[0]), np.sqrt(x[1]) / 0.664, np.sqrt(x[2])
    return out


def standstill_density(segments: list[np.ndarray], dt: float) -> np.ndarray:
    """White-noise density ``(C,)`` from samples at standstill: the RMS of each segment's samples
    about the segment's mean, times ``sqrt(dt)`` (the sensor's noise, vibration included)."""
    centred = [s - s.mean(0) for s in segments if len(s) >= 10]
    if not centred:
        raise ValueError("no standstill segment with at least 10 samples")
    pooled = np.concatenate(centred)
    return np.sqrt(np.mean(pooled**2, 0)) * np.sqrt(dt)


__all__ = ["allan_deviation", "fit_allan", "standstill_density"]
