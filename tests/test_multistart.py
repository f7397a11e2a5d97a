"""multistart and fit_fleet in one process: each start's result is the plain `fit` from that start; the best is
the lowest cost; failed starts are recorded, not raised; bad arguments are named before any fit. (Across
processes: tests/test_distributed.py.)

Problem: paper 000's static force map of the MAS-10 (9 lengths x 7 pressures, 2 N noise), 7 free parameters;
each fit converges in < 15 iterations, all fits share one compilation."""

import equinox as eqx
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
    broken = eqx.tree_at(lambda m: m.force_law.k0, start, start.force_law.k0 * np.nan)  # with_values refuses NaN
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
        # option values are checked as `fit` checks them, before any fit (max_steps=-3 was "every start failed")
        (dict(max_steps=-3), "max_steps must be a positive int, got -3"),
        (dict(max_steps="ten"), "max_steps must be a positive int, got 'ten'"),
        (dict(ftol=2.0), r"ftol must be a number in \[0, 1\), got 2.0"),
        (dict(stall_steps=0), "stall_steps must be a positive int"),
        (dict(solver="lm"), "solver must be None, a pamjax.LevenbergMarquardt or an optimistix"),
        (dict(identifiability_tol=2.0), r"identifiability_tol must be a number in \(0, 1\), got 2.0"),  # every start
        # the seed: None or an integer >= 0 (NumPy's ValueError / TypeError, or a bool taken as 1, before)
        (dict(seed=-1), "seed must be None or an integer >= 0, got -1"),
        (dict(seed="abc"), "seed must be None or an integer >= 0, got 'abc'"),
        (dict(seed=True), "seed must be None or an integer >= 0, got True"),
        (dict(seed=1.5), "seed must be None or an integer >= 0, got 1.5"),
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
    # a bad option value: every member failed, without an exception, before
    for value in (-3, "ten"):
        with pytest.raises(PamjaxInputError, match=f"max_steps must be a positive int, got {value!r}"):
            pj.fit_fleet(muscle, {"a": [exp], "b": [exp]}, FREE, max_steps=value, progress=False)
    with pytest.raises(PamjaxInputError, match=r"identifiability_tol must be a number in \(0, 1\), got 2.0"):
        pj.fit_fleet(muscle, {"a": [exp], "b": [exp]}, FREE, identifiability_tol=2.0, progress=False)  # all failed


def test_a_fresh_seed_is_recorded_and_drawn_once_for_every_process(problem, monkeypatch):
    """seed=None draws fresh starts; the seed drawn is `result.seed`, which draws them again. Spread over processes,
    each process drew its own, so the starts recorded were not the ones the other processes fitted: now process 0's
    seed is sent to every process (emulated here: `gather_bytes` hands this process process 0's value)."""
    import pamjax._core.distributed as distributed
    from pamjax._fit import multistart as multistart_module

    muscle, exp, space = problem
    fresh = pj.multistart(muscle, [exp], FREE, starts=3, seed=None, spread=0.4, max_steps=1, progress=False)
    assert isinstance(fresh.seed, int) and fresh.seed >= 0
    again = pj.multistart(muscle, [exp], FREE, starts=3, seed=fresh.seed, spread=0.4, max_steps=1, progress=False)
    np.testing.assert_array_equal(again.starts, fresh.starts)
    assert again.seed == fresh.seed and pj.multistart(muscle, [exp], FREE, starts=np.asarray(fresh.starts[:1]),
                                                      max_steps=1, progress=False).seed is None
    sent = []
    monkeypatch.setattr(distributed, "gather_bytes", lambda payload: sent.append(payload) or [b"1234", payload])
    values, seed = multistart_module._start_values(space, 3, None, 0.4, True)
    assert seed == 1234 and len(sent) == 1  # process 0's, on this process
    np.testing.assert_array_equal(values, multistart_module._start_values(space, 3, 1234, 0.4)[0])
    assert multistart_module._start_values(space, 3, 7, 0.4, True)[1] == 7 and len(sent) == 1  # a seed: no exchange


def test_experiments_and_draw_settings_with_given_starts_are_refused_before_any_fit(problem):
    """No experiments ran every start and failed each; a fleet member's experiments of None was recorded as a failed
    member; spread (even -5) and seed were silently ignored with an array of starts."""
    muscle, exp, space = problem
    with pytest.raises(PamjaxInputError, match="experiments must be a non-empty list"):
        pj.multistart(muscle, [], FREE, starts=3, max_steps=1, progress=False)
    with pytest.raises(PamjaxInputError, match="fleet member 'b': experiments must be pamjax experiments"):
        pj.fit_fleet(muscle, {"a": [exp], "b": None}, FREE, max_steps=1, progress=False)
    rows = np.tile(np.asarray(space.initial_values()), (2, 1))
    with pytest.raises(PamjaxInputError, match="spread must be a number >= 0"):
        pj.multistart(muscle, [exp], FREE, starts=rows, spread=-5.0, seed=123, progress=False)
    for given, shown in ((dict(spread=0.3), "spread=0.3"), (dict(seed=7), "seed=7"), (dict(seed=None), "seed=None")):
        with pytest.raises(PamjaxInputError, match=f"{shown}: spread and seed draw the starts"):
            pj.multistart(muscle, [exp], FREE, starts=rows, progress=False, **given)


def test_a_progress_that_is_neither_a_flag_nor_a_callable_is_refused_before_any_fit(problem):
    # progress="yes" failed with a raw TypeError after the first fit had run
    muscle, exp, _ = problem
    with pytest.raises(PamjaxInputError, match=r"progress must be True, False or a callable .*'yes'"):
        pj.multistart(muscle, [exp], FREE, starts=2, max_steps=1, progress="yes")


def test_results_gathered_from_other_processes_carry_what_a_single_process_result_carries(problem):
    """Spread over processes, each result came back through JSON without its experiments and predictions, so every
    process's `best` was refused by `profile_likelihood`. Emulated in one process: the gathering path of `_run_fits`
    (its payload through JSON) against the plain one, for a list of experiments and a single one (`fit_fleet`)."""
    from pamjax._fit import multistart as multistart_module

    muscle, exp, space = problem
    start = space.with_values(np.asarray(space.initial_values()) * 0.9)
    tasks = [("a", muscle, [exp]), ("b", start, exp)]
    plain = multistart_module._run_fits(tasks, FREE, dict(max_steps=30), False, False, "x")
    gathered = multistart_module._run_fits(tasks, FREE, dict(max_steps=30), True, False, "x")
    for (alone, *_), (sent, *_) in zip(plain, gathered):
        assert fit_fields(sent) == fit_fields(alone)
        assert eqx.tree_equal(sent.model, alone.model) and eqx.tree_equal(sent.experiments, alone.experiments)
        assert sent.predictions.keys() == alone.predictions.keys()
        for name, channels in alone.predictions.items():
            for channel, values in channels.items():
                np.testing.assert_array_equal(sent.predictions[name][channel], values)  # bitwise, NaN alike
    profile = pj.profile_likelihood(gathered[0][0], ["force_law.k0"], max_points=2, progress=False)
    assert profile.profiles[0].verdict  # profiled, not refused
