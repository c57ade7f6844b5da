"""One process's view of a job: it holds every item, gathers its own object, and a failure is
its own (the two-process runs are in tests/cli/test_train.py)."""

import numpy as np
import pytest

from jbevo.cli import common
from jbevo.training.distributed import agree, gather_objects, initialize, is_main, share


def test_one_process_shares_everything_and_gathers_its_object():
    assert is_main() and share([3, 1, 2]) == [3, 1, 2]
    (got,) = gather_objects({"a": np.arange(3)})
    np.testing.assert_array_equal(got["a"], np.arange(3))


def test_a_failure_is_agreed_on():
    agree(None)
    with pytest.raises(RuntimeError, match="^no IMU$"):
        agree("no IMU")
    with pytest.raises(common.CommandError, match="^sequence 09 is missing$"):
        with common.together():
            raise common.CommandError("sequence 09 is missing")
    with common.together():
        value = 1
    assert value == 1


def test_a_process_id_outside_the_job_is_refused():
    with pytest.raises(ValueError, match=r"process id 2 is outside \[0, 2\)"):
        initialize("localhost:1", 2, 2)
