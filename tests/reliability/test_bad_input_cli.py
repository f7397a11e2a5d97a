"""Every case of the file and command-line catalogue (`bad_inputs_cli.py`, issue 15) ends in a correct result or
one clear named error before any work: no silent wrong result, no lost work, no traceback. The slow cases (a fresh
process, a 1,000 s solve) run in `benchmarks/reliability.py` and, for the signals, in `test_cli_workflow.py`."""

import pytest

from .bad_inputs_cli import CASES, SLOW, verdict


def test_catalogue_covers_every_class():
    classes = {c for c, *_ in CASES.values()}
    assert {"config", "csv", "units", "paths", "concurrency", "interrupts", "resume", "solve", "model"} <= classes
    assert len(CASES) >= 50


@pytest.mark.parametrize("name", sorted(set(CASES) - SLOW))
def test_case_ends_in_a_correct_result_or_a_named_error(name):
    result, text = verdict(name)
    assert result == "ok", f"{name}: {result}: {text}"
