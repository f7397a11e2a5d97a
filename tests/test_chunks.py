"""Long fixed-grid runs are solved in pieces (`pamjax._solve.chunks`, issue 33): a 19,000 s run of the fitted
stick-slip model took 9.3 GB in one solve. The pieces join into the run one solve gives (same grid; rounding only),
share one compiled program, keep a failed run's status and NaN, and a run that cannot be cut and would not fit in
memory is refused with its estimate. Pieces are made small here (`PIECE_STEPS`) so that short runs exercise them;
the memory itself is measured in `benchmarks/reliability.py` (the catalogue's slow case)."""

import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import PamjaxInputError, presets
from pamjax._solve import chunks

CHANNELS = ("pressure", "position", "velocity", "mass_flow", "friction_force")


@pytest.fixture
def small_pieces(monkeypatch):
    monkeypatch.setattr(chunks, "PIECE_STEPS", 3000)
    return chunks


def _compare(system, signal, ts, small_pieces, monkeypatch, **kwargs):
    pieced = pamjax.simulate(system, signal, ts, **kwargs)
    monkeypatch.setattr(small_pieces, "PIECE_STEPS", 10**9)  # the same run in one solve
    whole = pamjax.simulate(system, signal, ts, **kwargs)
    assert bool(pieced.succeeded) and bool(whole.succeeded)
    for c in CHANNELS:
        a, b = np.asarray(pieced.channel(c)), np.asarray(whole.channel(c))
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.max(np.abs(b)), err_msg=c)
    np.testing.assert_array_equal(np.asarray(pieced.t), np.asarray(ts))
    return pieced, whole


@pytest.mark.parametrize("valve", ["averaged", "pwm"])
def test_pieces_join_into_the_run_one_solve_gives(valve, small_pieces, monkeypatch):
    # stick-slip friction (fixed grid); the triangle reaches duty 0.95, where the PWM valve stays open across period
    # starts: those are never cut points (the grid assumes a closed valve before its first period)
    system = presets.mas10_system(valve, friction="karnopp")
    ts = np.arange(0, 1201) * 0.01  # 12 s: ~12,000 grid steps (1 ms) or ~10,800 PWM intervals: 4 or more pieces
    signal = pamjax.Triangle(0.05, 0.95, 0.25)
    plan = chunks.plan(system, signal, ts, 0.0, "grid" if valve == "averaged" else "pwm", 16, 1e-3,
                       12000 if valve == "averaged" else 600)
    assert plan is not None and len(plan) >= 4
    assert len({last - first for first, last, _ in plan}) == 1  # one length: one compiled program for all
    if valve == "pwm":
        frequency = float(system.valve.pwm_frequency)
        for first, _, _ in plan[1:]:
            assert abs(ts[first] * frequency - round(ts[first] * frequency)) < 1e-9  # a period start
    _compare(system, signal, ts, small_pieces, monkeypatch)


def test_a_piece_that_fails_ends_the_run_with_its_status_and_nan(small_pieces):
    import equinox as eqx

    system = presets.mas10_system("averaged", friction="karnopp")
    flipped = eqx.tree_at(lambda s: s.valve.coefficients, system, system.valve.coefficients.at[1, 0].set(-0.0017))
    ts = np.arange(0, 1201) * 0.01
    traj = pamjax.simulate(flipped, pamjax.Constant(0.5), ts, throw=False)
    assert int(traj.result) != 0 and traj.pressure.shape == ts.shape
    assert np.all(np.isnan(np.asarray(traj.pressure)))
    with pytest.raises(pamjax.PamjaxSolveError, match="negative inflow"):
        pamjax.simulate(flipped, pamjax.Constant(0.5), ts)


def test_a_run_that_cannot_be_cut_and_would_not_fit_is_refused_with_its_estimate(small_pieces, monkeypatch):
    system = presets.mas10_system("averaged", friction="karnopp")
    ts = np.arange(0, 1201) * 0.01 + 3e-4 * np.sin(np.arange(1201))  # times off the 1 ms grid: no cut point
    ts[0] = 0.0
    monkeypatch.setattr(small_pieces, "_available_memory", lambda: 1_000_000)  # 1 MB free
    with pytest.raises(PamjaxInputError, match=r"needs about [\d.]+ GB of memory to solve in one piece, more than the "
                                               r"0\.0 GB available.*give output times on its grid"):
        pamjax.simulate(system, pamjax.Constant(0.5), jnp.asarray(ts))
    # the advice works: the same run with output times on its grid is cut into pieces, in the same 1 MB
    on_grid = np.arange(0, 1201) * 0.01
    assert bool(pamjax.simulate(system, pamjax.Constant(0.5), jnp.asarray(on_grid)).succeeded)
    monkeypatch.setattr(small_pieces, "_available_memory", lambda: 64 * 2**30)  # it fits: solved whole
    assert bool(pamjax.simulate(system, pamjax.Constant(0.5), jnp.asarray(ts)).succeeded)
