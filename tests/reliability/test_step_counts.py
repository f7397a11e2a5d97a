"""Regression guard: solver step counts of the benchmark experiments must not grow by more than 10 % (+ 5) over the
recorded `step_counts.json`. Counts are not times, but neither are they exactly machine-independent: another CPU's
last-bit differences can move an adaptive step pattern by a few steps (issue 15), so the test asserts a bound with
that margin, never the recorded number. Re-record deliberately with `python -m tests.reliability.step_counts
--write` after a change that is meant to alter them."""

import json
import pathlib

import pytest

from .step_counts import experiments

RECORDED = json.loads((pathlib.Path(__file__).parent / "step_counts.json").read_text())


@pytest.mark.parametrize("name", sorted(RECORDED))
def test_step_counts_do_not_grow(name):
    traj = experiments()[name]()
    assert bool(traj.succeeded)
    for key, attribute in (("steps", "num_steps"), ("accepted", "num_accepted_steps"),
                           ("rejected", "num_rejected_steps")):
        now, then = int(getattr(traj, attribute)), RECORDED[name][key]
        assert now <= 1.10 * then + 5, f"{name}: {key} grew from {then} to {now} (> 10 %)"
