"""multistart and fit_fleet in one process: each start's result is the plain `fit` from that start; the best is
the lowest cost; failed starts are recorded, not raised; bad arguments are named before any fit. (Across
processes: tests/test_distributed.py.)

Problem: paper 000's static force map of the MAS-10 (9 lengths x 7 pressures, 2 N noise), 7 free parameters;
each fit converges in < 15 iterations, all fits share one compilation."""

import numpy as np
import pytest
from problems import FORCE_MAP_FREE, fit_fields, force_map

import pamjax as pj
from pamjax import PamjaxInputError, PamjaxSolveError

FREE = FORCE_MAP_FREE


@pytest.fixture(scope="module")
def problem():
    muscle, exp = force_map()
    space = pj.ParameterSpace(muscle, FREE)
    return muscle, exp, space


def test_each_start_is_the_plain_fit_and_the_best_is_the_lowest_cost(problem):
    muscle, exp, space = problem
    lines = []
    result = pj.multistart(muscle, [exp], FREE, starts=4, seed=1, spread=0.4, max_steps=30, progress=lines.append)
    assert len(lines) == 4 and "start 3 (4/4)" in lines[-1]
    np.testing.assert_array_equal(result.starts[0], np.asarray(space.initial_values()))  # start 0: the model's
    assert len({tuple(s) for s in result.starts}) == 4 and result.labels == space.labels
    assert result.errors == [None] * 4 and result.processes == [0] * 4
    costs = result.costs
    assert result.best_index == int(np.argmin(costs)) and result.best.cost == costs.min()
    for i in (0, 3):
        alone = pj.fit(space.with_values(result.starts[i]), [exp], FREE, max_steps=30, progress=False)
        assert fit_fields(alone) == fit_fields(result.results[i])
    assert "*" in result.table().splitlines()[result.best_index + 1]
    # the drawn starts depend on the seed only
    again = pj.multistart(muscle, [exp], FREE, starts=4, seed=1, spread=0.4, max_steps=1, progress=False)
    np.testing.assert_array_equal(again.starts, result.starts)
    other = pj.multistart(muscle, [exp], FREE, starts=2, seed=2, spread=0.4, max_steps=1, progress=False)
    assert not np.array_equal(other.starts[1], result.starts[1])


def test_failed_starts_are_recorded_and_all_failed_raises(problem):
    muscle, exp, space = problem
    values = np.asarray(space.initial_values())
    starts = np.stack([values * 0.8, values, values * 1.2])
    starts[1, 5] = np.nan  # k0
    result = pj.multistart(muscle, [exp], FREE, starts=starts, max_steps=30, progress=False)
    assert result.results[1] is None and "PamjaxInputError" in result.errors[1] and "non-finite" in result.errors[1]
    assert result.results[0].converged and result.results[2].converged and result.best_index in (0, 2)
    assert np.isinf(result.costs[1]) and "failed" in result.table()
    with pytest.raises(PamjaxSolveError, match="every start failed"):
        pj.multistart(muscle, [exp], FREE, starts=starts[1:2], progress=False)


def test_identifiability_warned_once_for_the_best(problem):
    muscle, exp, _ = problem
    free = ["force_law.k0", "force_law.k1", "force_law.k2"]
    with pytest.warns(pj.PamjaxIdentifiabilityWarning) as caught:
        pj.multistart(muscle, [exp], free, starts=3, max_steps=5, progress=False)
    assert len(caught) == 1


def test_fleet_fits_each_member_and_records_failures():
    muscle, exp_a = force_map(seed=0)
    _, exp_b = force_map(seed=1)
    space = pj.ParameterSpace(muscle, FREE)
    start = space.with_values(np.asarray(space.initial_values()) * 0.9)
    broken = space.with_values(np.asarray(space.initial_values()) * np.nan)
    fleet = pj.fit_fleet({"a": start, "b": start, "c": broken}, {"a": [exp_a], "b": exp_b, "c": [exp_a]}, FREE,
                         max_steps=30, progress=False)
    assert fleet.failed == ["c"] and fleet.results["c"] is None and "non-finite" in fleet.errors["c"]
    for name, exp in (("a", exp_a), ("b", exp_b)):
        alone = pj.fit(start, [exp], FREE, max_steps=30, progress=False)
        assert fit_fields(fleet.results[name]) == fit_fields(alone)
    assert fleet.results["a"].values != fleet.results["b"].values  # different data, different fits
    assert "failed" in fleet.table()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(starts=0), "starts must be >= 1"),
        (dict(starts=np.ones((2, 3))), r"starts must be a count or an array \(n_starts, 7\)"),
        (dict(spread=-1.0), "spread must be a number >= 0"),
        (dict(spread=[0.1, 0.2]), "spread must be a number >= 0 or one per parameter"),
        (dict(max_stepz=3), "unknown fit option 'max_stepz'"),
        (dict(out="x.json"), "'out' is not passed to the individual fits"),
        (dict(distributed="yes"), "distributed must be None, True or False"),
    ],
)
def test_bad_arguments_are_named_before_any_fit(problem, kwargs, match):
    muscle, exp, _ = problem
    with pytest.raises(PamjaxInputError, match=match):
        pj.multistart(muscle, [exp], FREE, progress=False, **kwargs)


def test_fleet_bad_arguments():
    muscle, exp = force_map()
    with pytest.raises(PamjaxInputError, match="fleet must be a non-empty dict"):
        pj.fit_fleet(muscle, [exp], FREE)
    with pytest.raises(PamjaxInputError, match=r"no start model for fleet members \['b'\]"):
        pj.fit_fleet({"a": muscle}, {"a": [exp], "b": [exp]}, FREE)
    with pytest.raises(PamjaxInputError, match="fleet member 'a': unknown parameter"):
        pj.fit_fleet(muscle, {"a": [exp]}, ["force_law.k9"])
