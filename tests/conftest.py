"""Shared test set-up: float64 available everywhere, reference data from $JBEVO_REFERENCE_DATA."""

import os
from pathlib import Path

import jax
import pytest

# Exactness tests need float64; float32 tests ask for float32 arrays explicitly.
jax.config.update("jax_enable_x64", True)


@pytest.fixture
def reference_data() -> Path:
    """The shared reference-data folder; skips the test when it is not configured."""
    root = os.environ.get("JBEVO_REFERENCE_DATA")
    if not root:
        pytest.skip("JBEVO_REFERENCE_DATA is not set")
    path = Path(root)
    if not path.is_dir():
        pytest.fail(f"JBEVO_REFERENCE_DATA={root} is not a folder")
    return path
