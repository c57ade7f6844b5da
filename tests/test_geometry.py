import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from jbevo.geometry import se2_between, se2_compose, wrap_angle

finite = st.floats(-50.0, 50.0, allow_nan=False)


@settings(deadline=None, max_examples=200)
@given(finite)
def test_wrap_angle_range_and_equivalence(a):
    w = float(wrap_angle(jnp.float64(a)))
    assert -np.pi <= w < np.pi + 1e-12
    assert abs(np.sin(w) - np.sin(a)) < 1e-9 and abs(np.cos(w) - np.cos(a)) < 1e-9


def test_wrap_angle_edges_and_gradient():
    np.testing.assert_allclose(wrap_angle(jnp.array([np.pi, -np.pi, 0.0, 3 * np.pi])), [-np.pi, -np.pi, 0.0, -np.pi])
    assert float(jax.grad(wrap_angle)(2.0)) == 1.0


@settings(deadline=None, max_examples=100)
@given(finite, finite, finite, finite, finite, finite)
def test_se2_between_inverts_compose(x, y, yaw, dx, dy, dyaw):
    pose = jnp.array([x, y, yaw])
    inc = jnp.array([dx, dy, float(wrap_angle(dyaw))])
    back = se2_between(pose, se2_compose(pose, inc))
    np.testing.assert_allclose(back, inc, atol=1e-9)


def test_se2_compose_frames():
    # facing +y (yaw = pi/2), moving 1 m forward and 1 m left ends at (-1, 1)
    out = se2_compose(jnp.array([0.0, 0.0, np.pi / 2]), jnp.array([1.0, 1.0, 0.0]))
    np.testing.assert_allclose(out, [-1.0, 1.0, np.pi / 2], atol=1e-12)
