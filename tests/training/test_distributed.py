"""One process's view of a job: it holds every item and gathers only its own object (the
two-process runs are in tests/cli/test_train.py)."""

import pytest

from jbevo.training.distributed import gather_objects, initialize, is_main, share


def test_one_process_shares_everything():
    assert is_main() and share([3, 1, 2]) == [3, 1, 2] and gather_objects({"a": [1]}) == [{"a": [1]}]


def test_a_process_id_outside_the_job_is_refused():
    with pytest.raises(ValueError, match=r"process id 2 is outside \[0, 2\)"):
        initialize("localhost:1", 2, 2)
