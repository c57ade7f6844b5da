"""Shared test set-up.

* jbevo's jaxtyping annotations are checked at run time (shapes and dtypes of every annotated
  argument and return value, with beartype), for every module the tests import.
* The suite runs in float32, the default users get; tests that need float64 (exactness against
  an independent reference, finite-difference gradient checks) ask for the ``float64`` fixture.
* Reference data comes from ``$JBEVO_REFERENCE_DATA``; tests that need it skip without it.
* JAX's compilation caches are cleared after each test module.
"""

import gc
import os
from pathlib import Path

from jaxtyping import install_import_hook

import tests.typecheck  # noqa: F401  (the hook looks the checker up by its dotted name)

# Before any jbevo module is imported: every one imported from here on is checked.
_HOOK = install_import_hook("jbevo", "tests.typecheck.checker")

import jax  # noqa: E402
import jaxtyping  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture
def float64():
    """Run the test with ``jax_enable_x64``: float64 by default."""
    with jax.enable_x64(True):
        yield


@pytest.fixture
def as_users_run():
    """Turn the run-time shape checks off, as they are for users: for tests of the errors that
    jbevo's own input checks raise (a shape check would catch the bad input first)."""
    jaxtyping.config.update("jaxtyping_disable", True)
    try:
        yield
    finally:
        jaxtyping.config.update("jaxtyping_disable", False)


@pytest.fixture(scope="session")
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
