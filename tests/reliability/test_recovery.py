"""Recovery from random starts, small version of `benchmarks/reliability_recovery.py` (issue 7 item 5, issue 3's
"from 20 random starts at least 18 reach the same optimum"): the same joint problem (triangle run + tank charge +
static force map, averaged valve, 8 parameters) at 25 Hz, 5 seeded starts at ±30 %; every start must end on the best
cost plateau (within 1 % of the lowest final cost) and at the same parameters (within 0.1 reported standard error
of the best start). Accuracy against the truth is `tests/test_fit.py`'s job (at 25 Hz with this noise seed the
viscous coefficient ends 3.2 standard errors from the truth; at the benchmark's 50 Hz every parameter is within 0.6).

Compilation happens once (fits of one problem structure share it): about 40 s of this test on a loaded 2-core
machine, the 5 fits a few seconds each."""

import importlib.util
import pathlib

import numpy as np

_PATH = pathlib.Path(__file__).resolve().parents[2] / "benchmarks" / "reliability_recovery.py"
_spec = importlib.util.spec_from_file_location("reliability_recovery", _PATH)
recovery = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(recovery)


def test_all_random_starts_reach_the_best_plateau():
    labels, truth, results = recovery.run_starts(5, verbose=False, rate=25.0)
    rate, rate_20 = recovery.summarise(labels, truth, results, verbose=False)
    costs = np.array([r.cost for r in results])
    assert rate == 1.0 and rate_20 == 1.0, costs
    assert all(r.converged for r in results), [r.status for r in results]
    # the starts really were spread out (a start at the truth would make the test vacuous)
    starts = np.array([r.initial_values for r in results])
    assert np.all(np.max(np.abs(starts / truth - 1), axis=0) > 0.1)
    assert np.all(np.array([r.initial_cost for r in results]) > 100 * costs.max())
    best = results[int(np.argmin(costs))]
    se = np.asarray(best.standard_errors)
    assert np.all(np.isfinite(se) & (se > 0))
    values = np.array([r.values for r in results])
    spread = np.max(np.abs(values - best.values), axis=0) / se
    assert np.all(spread < 0.1), dict(zip(labels, spread))
