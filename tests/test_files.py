import json

import pytest

from jbevo.files import write_json_atomic


def test_writes_json_and_creates_folders(tmp_path):
    path = tmp_path / "a" / "b" / "metrics.json"
    write_json_atomic(path, {"x": 1.5, "y": [1, 2]})
    assert json.loads(path.read_text()) == {"x": 1.5, "y": [1, 2]}


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "metrics.json"
    write_json_atomic(path, {"ok": True})
    with pytest.raises(TypeError):
        write_json_atomic(path, {"bad": object()})  # not JSON serialisable
    assert json.loads(path.read_text()) == {"ok": True}
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.json"]
