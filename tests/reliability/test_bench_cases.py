"""Every case of the bench-folder catalogue (`bench_cases.py`, issue 33: `fits/joint.py`, `pamjax fit` with a
`[bench]`, `load_bench` on a folder damaged one way at a time) ends in one named error: exit status 2, no traceback,
no output folder left behind."""

import pytest

from . import bench_cases
from .bad_inputs_cli import verdict

NAMES = bench_cases.register()


@pytest.mark.parametrize("name", NAMES)
def test_case_ends_in_a_named_error(name):
    result, text = verdict(name)
    assert result == "ok", f"{name}: {result}: {text}"
