"""The MAS-10 preset's exhaust silencer (paper 000, Fig. 12 text): `PorousRestriction` against Darcy's compressible law
(`pamjax._physics.gas`), the preset's permeance (`presets.mas10_silencer`) re-derived from its stated rule by an
independent NumPy computation, the silencer in series with the exhaust port, and bad input."""

import equinox as eqx
import jax
import numpy as np
import pytest
from helpers import P_ATM, np_ellipse_flow
from scipy.optimize import brentq

import pamjax as pj
from pamjax import presets

AIR = pj.Air()

# A restriction's flow and its slope jitted once per restriction type, the pressures as array arguments: called
# eagerly, every operation (and the series' bisection loop) would compile a program of its own.
_mass_flow = eqx.filter_jit(lambda restriction, p1, p2: restriction.mass_flow(p1, p2, AIR))
_slope_p1 = eqx.filter_jit(jax.grad(lambda p1, restriction, p2: restriction.mass_flow(p1, p2, AIR)))


def _flow(restriction, p1, p2):
    return float(_mass_flow(restriction, np.asarray(p1, dtype=float), np.asarray(p2, dtype=float)))


def test_porous_restriction_is_darcy():
    k = 2e-14
    r = pj.PorousRestriction(k)
    for p1, p2 in ((6e5, P_ATM), (P_ATM, 3e5), (2e5, 2e5)):
        assert _flow(r, p1, p2) == pytest.approx(k * (p1**2 - p2**2), rel=1e-14, abs=1e-20)
    slope = _slope_p1(np.asarray(2e5), r, np.asarray(2e5))
    assert float(slope) == pytest.approx(2 * k * 2e5, rel=1e-12)  # finite slope at equal pressures: laminar


def test_preset_permeance_follows_its_rule():
    """Rule (presets docstring item 5): with the silencer, the exhaust path passes 98 % of its unsilenced choked flow
    from 0.65 MPa to atmosphere. Solved here with the eq. 11 oracle and SciPy: the port's outlet p_m, then K."""
    port = lambda p1, p2: np_ellipse_flow(p1, p2, 0.39, 0.49, 3.14e-6)  # noqa: E731
    target = 0.98 * port(6.5e5, P_ATM)
    pm = brentq(lambda q: port(6.5e5, q) - target, 0.49 * 6.5e5, 6.5e5 * 0.999)
    assert presets.MAS10_SILENCER_PERMEANCE == pytest.approx(target / (pm**2 - P_ATM**2), rel=1e-4)
    exhaust = presets.mas10_valve(silencer=True).exhaust
    ratio = _flow(exhaust, 6.5e5, P_ATM) / port(6.5e5, P_ATM)
    assert ratio == pytest.approx(0.98, abs=1e-4)
    low = _flow(exhaust, 1.2e5, P_ATM) / port(1.2e5, P_ATM)
    assert 0.15 < low < 0.3  # near atmosphere the silencer throttles: the slow end of a discharge (Fig. 12)


def test_silencer_raises_the_deflation_steady_state():
    """A 50 cm³ tank deflated from supply at duty 0.25 (Fig. 12) ends higher with the silencer."""
    ts = np.linspace(0.0, 1.0, 11)
    ends = []
    for silencer in (False, True):
        tank = presets.mas10_tank_system("exact", silencer=silencer)
        traj = pj.simulate(tank, pj.Constant(0.25), ts, y0=tank.initial_state(6.5e5), stepping="pwm")
        ends.append(float(np.asarray(traj.pressure)[-1]))
    assert ends[1] - ends[0] > 3e4  # Pa: the offset the paper attributes to its silencer


def test_bad_input_is_named():
    with pytest.raises(pj.PamjaxInputError, match="silencer applies to the switching valve"):
        presets.mas10_system("averaged", silencer=True)
    with pytest.raises(pj.PamjaxInputError, match="silencer must be True, False or a restriction"):
        presets.mas10_valve(silencer="U-M7")
    with pytest.raises(pj.PamjaxInputError, match="permeance"):
        pj.PorousRestriction(-1.0)


def test_series_restriction_is_elementwise_in_the_pressures():
    # the intermediate pressure's Newton step took jax.grad of an elementwise residual: arrays of pressures raised
    # "Gradient only defined for scalar-output functions", while every other restriction is elementwise
    valve = presets.mas10_valve(silencer=True)
    p = np.array([6.5e5, 3e5, 1.5e5])
    flows = np.asarray(valve.exhaust.mass_flow(p, P_ATM, AIR))
    np.testing.assert_allclose(flows, [float(valve.exhaust.mass_flow(q, P_ATM, AIR)) for q in p], rtol=1e-12)
    assert np.asarray(valve.mass_flow_at_opening(0.0, p, AIR)).shape == (3,)


@pytest.mark.parametrize("make, match", [
    (lambda port: pj.SeriesRestriction(port, "silencer"), r"SeriesRestriction\.second must be an AbstractRestriction"),
    (lambda port: pj.SeriesRestriction(None, port), r"SeriesRestriction\.first must be an AbstractRestriction"),
    # 0 halvings gave the flow the wrong sign, 1 a flow 13 times too large
    (lambda port: pj.SeriesRestriction(port, presets.mas10_silencer(), iterations=0), r"iterations must be an int of "
     r"at least 50"),
    (lambda port: pj.SeriesRestriction(port, presets.mas10_silencer(), iterations=10), r"iterations must be at least "
     r"50, got 10: fewer halvings leave the intermediate pressure unconverged"),
])
def test_series_restriction_refuses_a_part_that_is_no_restriction_or_too_few_iterations(make, match):
    with pytest.raises(pj.PamjaxInputError, match=match):
        make(pj.EllipseRestriction(0.39, 0.49, 3.14e-6))
