"""bench.atomic: an output is replaced whole or not at all, and no temporary file is left."""
import json
import os

import numpy as np
import pytest

from bench import atomic


def test_a_failed_write_keeps_the_last_complete_file(tmp_path):
    path = tmp_path / "records.jsonl"
    atomic.write_jsonl(path, [{"a": 1}, {"b": 2}])
    assert [json.loads(line) for line in path.read_text().splitlines()] == [{"a": 1}, {"b": 2}]

    def half(tmp):  # a run killed while writing: part of the new file, then an exception
        with open(tmp, "w") as f:
            f.write('{"c": 3}\n{"d"')
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic.write(path, half)
    assert [json.loads(line) for line in path.read_text().splitlines()] == [{"a": 1}, {"b": 2}]
    assert os.listdir(tmp_path) == ["records.jsonl"]


def test_write_all_replaces_a_group_together_or_not_at_all(tmp_path):
    a, b = tmp_path / "reference.json", tmp_path / "x.npy"
    atomic.write_text(a, "old")
    atomic.save_npy(b, np.arange(3.0))

    def fails(tmp):
        raise OSError("disk full")

    with pytest.raises(OSError):
        atomic.write_all([(a, atomic.text_writer("new")), (b, fails)])
    assert a.read_text() == "old" and np.load(b).tolist() == [0.0, 1.0, 2.0]  # neither replaced
    assert sorted(os.listdir(tmp_path)) == ["reference.json", "x.npy"]
    atomic.write_all([(a, atomic.text_writer("new")), (b, lambda t: np.save(t, np.ones(2)))])
    assert a.read_text() == "new" and np.load(b).tolist() == [1.0, 1.0]
