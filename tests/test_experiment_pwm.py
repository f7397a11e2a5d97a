"""Fits with the switching (PWM) valve: experiments step on the PWM-synchronous grid, so the residuals are smooth,
deterministic functions of the parameters; a small tank fit converges and recovers the truth within 3 standard
errors. Short horizons (0.6 s, 30 PWM periods) to keep compilation small. `Experiment(stepping=...)`
(`pamjax._fit.experiment`), its residuals and Jacobian (`pamjax._fit.problem`), the fit (`pamjax._fit.fit`)."""

import jax.numpy as jnp
import numpy as np
import pytest

import pamjax as pj
from pamjax import PamjaxInputError

FREE = ["valve.inflate.discharge_coefficient", "valve.inflate.critical_ratio",
        "valve.exhaust.discharge_coefficient", "valve.exhaust.critical_ratio"]
NOISE = 2e3  # Pa, the hybrid bench's pressure noise


def _tank():
    """Paper 000's valve (Table 1: C_v 0.36 / 0.39, b_v 0.28 / 0.49, 2 ms delays) on a 5e-5 m³ tank."""
    valve = pj.OnOffValve(inflate=pj.EllipseRestriction(0.36, 0.28), exhaust=pj.EllipseRestriction(0.39, 0.49),
                          supply_pressure=6.5e5, pwm_frequency=50.0, switch_on_delay=2e-3, switch_off_delay=2e-3)
    return pj.TankSystem(valve=valve, volume=5e-5)


def _experiments(truth, horizon=0.6):
    """Charge from atmosphere at duty 0.75 (path 1→2 up to p/p_s ≈ 0.9: both flow regimes) and discharge from supply
    at duty 0.25 (path 2→3 reaches the subsonic regime p < p_atm / b_v ≈ 2 bar; at higher duties the tank settles
    where inflow and exhaust balance, choked, and b_v of the exhaust has no effect)."""
    ts = np.arange(0.0, horizon + 1e-9, 0.01)
    exps = []
    for k, (u, p0) in enumerate(((0.75, 101325.0), (0.25, 6.5e5))):
        rec = pj.synthetic_recording(truth, pj.Constant(u), ts, noise=dict(pressure=NOISE), channels=["pressure"],
                                     y0=truth.initial_state(p0), seed=10 + k, name=f"run{k}", stepping="pwm",
                                     substeps=32)
        exps.append(pj.Experiment(rec, pj.Constant(u), scales=dict(pressure=NOISE), initial=dict(pressure=p0)))
    return exps


def test_pwm_tank_fit_recovers_truth_within_three_standard_errors():
    truth = _tank()
    exps = _experiments(truth)
    assert all(e.stepping == "auto" for e in exps)
    space = pj.ParameterSpace(truth, FREE)
    true_values = np.asarray(space.initial_values())
    # 30 % off; the other way round ([1.3, 0.7, 1.3, 0.7]) the exhaust's critical ratio goes where these runs do
    # not see it (0.56: the cost 42.54 against 42.51 at the truth) with C_v fitted through its logistic over (0, 1),
    # as with the log transform from 4 of 8 other starts
    start = space.with_values(true_values * np.array([0.7, 1.3, 0.7, 1.3]))
    res = pj.fit(start, exps, FREE, progress=False)
    assert res.converged, res.status
    assert res.accepted_steps >= 2 and res.cost < 0.01 * res.initial_cost
    se = np.asarray(res.standard_errors)
    assert np.all(np.isfinite(se)) and np.all(se > 0)
    z = (np.asarray(res.values) - true_values) / se
    assert np.all(np.abs(z) < 3), dict(zip(res.labels, z))
    # the noise (2 kPa) is what is left: RMSE within 30 % of it on every run
    for name, chans in res.channel_errors.items():
        assert 0.7 * NOISE < chans["pressure"]["rmse"] < 1.3 * NOISE, (name, chans)


def test_pwm_residuals_are_smooth_in_the_parameters():
    """Forward-mode Jacobian = central differences (h = 1e-5 in θ) to 1e-6: no step-pattern noise (an adaptive
    solve of the switching valve misses this by orders of magnitude at rtol 1e-6)."""
    truth = _tank()
    exps = tuple(e.bind(truth) for e in _experiments(truth, horizon=0.2))
    space = pj.ParameterSpace(truth, FREE[:2])
    def res(theta):
        return pj._fit.problem.residuals_at(space, theta, exps)

    theta = space.initial_theta()
    jac = np.asarray(pj._fit.problem.residuals_and_jacobian(space, theta, exps)[1])
    h = 1e-5
    for i in range(theta.size):
        d = jnp.zeros_like(theta).at[i].set(h)
        fd = (np.asarray(res(theta + d)) - np.asarray(res(theta - d))) / (2 * h)
        assert np.linalg.norm(fd - jac[:, i]) < 1e-6 * np.linalg.norm(jac[:, i]), space.labels[i]


def test_experiment_stepping_input_errors():
    truth = _tank()
    rec = pj.Recording(np.linspace(0, 0.1, 6), dict(pressure=np.full(6, 2e5)))
    with pytest.raises(PamjaxInputError, match="stepping must be"):
        pj.Experiment(rec, pj.Constant(0.5), stepping="rk4")
    with pytest.raises(PamjaxInputError, match="substeps"):
        pj.Experiment(rec, pj.Constant(0.5), substeps=1)
    averaged = pj.TankSystem(valve=pj.presets.mas10_averaged_valve(), volume=5e-5)
    exp = pj.Experiment(rec, pj.Constant(0.5), stepping="pwm")
    with pytest.raises(PamjaxInputError, match="stepping='pwm' needs a switching valve.*AveragedValve"):
        exp.check(averaged)
    exp.check(truth)  # the switching valve is fine
