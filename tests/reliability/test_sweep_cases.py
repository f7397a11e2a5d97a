"""Every case of the sweep and gradient catalogue (`sweep_cases.py`, issue 33) ends in a correct result or one clear
named error: stick-slip sweeps equal `simulate` point by point, from Python and `pamjax sweep`; the gradient check's
reference holds on the parameters it failed on. `benchmarks/reliability.py` counts them in `workflow_cases=`."""

import pytest

from . import sweep_cases
from .bad_inputs_cli import verdict

NAMES = sweep_cases.register()


def test_catalogue_has_both_classes():
    assert {c for c, *_ in sweep_cases.CASES.values()} == {"sweep", "gradients"}


@pytest.mark.parametrize("name", NAMES)
def test_case_ends_in_a_correct_result_or_a_named_error(name):
    result, text = verdict(name)
    assert result == "ok", f"{name}: {result}: {text}"
