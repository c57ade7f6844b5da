"""Shared test set-up: float64 available everywhere, reference data from $JBEVO_REFERENCE_DATA,
and JAX's compilation caches cleared after each test module."""

import gc
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


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """Every compiled executable keeps its code mapped; one test process compiles hundreds of
    them and ran past the kernel's limit on memory maps (65,530: XLA then segfaults while
    compiling). Clearing the caches after each module frees those of finished modules."""
    yield
    jax.clear_caches()
    gc.collect()
