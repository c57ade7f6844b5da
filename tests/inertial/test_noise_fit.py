"""The Allan deviation of simulated white noise and random walk, the noise model fitted back from
its curve, and the standstill density of a white noise."""

import numpy as np
import pytest

from jbevo.inertial.noise_fit import allan_deviation, fit_allan, standstill_density


def test_allan_deviation_of_white_noise_and_of_a_random_walk():
    rng = np.random.default_rng(0)
    dt, n, white, walk = 0.01, 200_000, 2e-3, 3e-4
    taus = np.array([0.01, 0.1, 1.0, 100.0, 600.0, 1000.0])
    adev = allan_deviation(rng.normal(0, white / np.sqrt(dt), (n, 2)), dt, taus)
    np.testing.assert_allclose(adev[:3] * np.sqrt(taus[:3, None]), white, rtol=0.05)  # N / sqrt(tau)
    assert np.all(np.isnan(adev[-1]))  # beyond a third of the record
    adev = allan_deviation(np.cumsum(rng.normal(0, walk * np.sqrt(dt), (n, 2)), 0), dt, taus)
    np.testing.assert_allclose(adev[3] / np.sqrt(taus[3] / 3), walk, rtol=0.3)  # K sqrt(tau / 3)


def test_fit_allan_recovers_the_noise_model():
    taus = np.logspace(-2, 3, 30)
    n, b, k = np.array([2e-3, 1e-4]), np.array([1e-4, 3e-5]), np.array([3e-4, 1e-6])
    adev = np.sqrt(n**2 / taus[:, None] + (0.664 * b) ** 2 + k**2 * taus[:, None] / 3)
    fit = fit_allan(taus, adev)
    np.testing.assert_allclose(fit["white"], n, rtol=1e-6)
    np.testing.assert_allclose(fit["bias_instability"], b, rtol=1e-5)
    np.testing.assert_allclose(fit["random_walk"], k, rtol=1e-4)


def test_standstill_density():
    rng = np.random.default_rng(1)
    segments = [rng.normal(k, 0.1, (500, 3)) for k in range(3)]
    np.testing.assert_allclose(standstill_density(segments, 0.01), 0.1 * 0.1, rtol=0.05)
    with pytest.raises(ValueError, match="standstill"):
        standstill_density([np.zeros((3, 3))], 0.01)
    with pytest.raises(ValueError, match="shape"):
        allan_deviation(np.zeros(5), 0.01, np.array([0.1]))
