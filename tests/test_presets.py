"""Presets: re-derive the numbers documented in `pamjax/presets.py` (fits/derive_presets.py) and check they are
physical."""

import importlib.util
import pathlib

import jax.numpy as jnp
import numpy as np
import pytest

from pamjax import PamjaxInputError, presets

_spec = importlib.util.spec_from_file_location(
    "derive_presets", pathlib.Path(__file__).resolve().parents[1] / "fits" / "derive_presets.py"
)
derive_presets = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(derive_presets)


@pytest.fixture(scope="module")
def derived():
    return derive_presets.derive(with_valve=True)


def test_mas10_force_and_volume_rederived(derived):
    m = derived["mas10"]
    # Printed with 9 significant digits (a_i), 10 (k0, k1), 8 (v0, v1): half a unit in the last place.
    np.testing.assert_allclose(m["a"], presets.MAS10_MAX_FORCE_COEFFICIENTS, rtol=5e-9)
    assert m["k0"] == pytest.approx(presets.MAS10_K0, rel=5e-9)
    assert m["k1"] == pytest.approx(presets.MAS10_K1, rel=5e-9)
    assert m["v0"] == pytest.approx(presets.MAS10_V0, rel=5e-8)
    assert m["v1"] == pytest.approx(presets.MAS10_V1, rel=5e-8)


def test_dmsp40_rederived(derived):
    d = derived["dmsp40"]
    np.testing.assert_allclose(d["a"], presets.DMSP40_MAX_FORCE_COEFFICIENTS, rtol=5e-9)
    assert d["k0"] == pytest.approx(presets.DMSP40_K0, rel=5e-9)
    assert d["k1"] == pytest.approx(presets.DMSP40_K1, rel=5e-9)
    np.testing.assert_allclose(d["volume_cubic"], presets.DMSP40_VOLUME_CUBIC, rtol=5e-6)  # printed to 6 digits


def test_averaged_valve_rederived(derived):
    # m1…m9 printed with 13 significant digits; the fit quality quoted in the presets docstring (12.8 %, 2.8 %);
    # m1 is pinned to 0.
    np.testing.assert_allclose(derived["mas10_averaged_valve"], presets.MAS10_AVERAGED_VALVE, rtol=5e-12, atol=1e-24)
    assert derived["averaged_valve_fit"]["max_error_percent"] == pytest.approx(12.8, abs=0.05)
    assert derived["averaged_valve_fit"]["rmse_percent"] == pytest.approx(2.8, abs=0.05)


def test_preset_muscle_is_physical():
    muscle = presets.mas10_muscle()
    xs = jnp.linspace(0.0, presets.MAS10_MAX_POSITION, 151)
    fmax = np.asarray(muscle.force_law.max_force(xs))
    assert np.all(np.diff(fmax) < 0)  # F_max decreases over the stroke
    assert fmax[0] == pytest.approx(630.0) and abs(fmax[-1]) < 20.0  # ~0 N at 25 % contraction
    assert np.all(np.asarray(muscle.force_law.pressure_slope(xs)) > 0)  # more pressure, more force
    system = presets.mas10_system("averaged")
    lo, hi = presets.MAS10_MIN_POSITION, presets.MAS10_MAX_POSITION
    positions = [float(system.equilibrium_position(jnp.asarray(p))) for p in (3e5, 4.5e5, 6e5 + 101325.0)]
    assert all(lo + 1e-3 < x < hi - 1e-3 for x in positions)  # 9.6 kg equilibria inside the stroke
    assert positions[0] < positions[1] < positions[2]  # higher pressure lifts it higher
    x_atm = float(system.equilibrium_position(jnp.asarray(101325.0)))  # unpressurised: stretched below x = 0
    assert lo <= x_atm < 0.0 < positions[0]
    assert presets.MAS10_V1 > 0 and presets.MAS10_V0 + presets.MAS10_V1 * hi > presets.MAS10_V0  # volume grows


@pytest.mark.parametrize("kwargs, match", [
    # each ended as an AttributeError inside simulate (None.mass_flow, 5.force, ...)
    (dict(valve=None), r"valve must be 'pwm' .* or a valve object \(an AbstractValve.*got NoneType None"),
    (dict(valve=123), r"valve must be 'pwm' .* or a valve object \(an AbstractValve.*got int 123"),
    (dict(friction=None), r"friction must be 'coulomb', .* or a friction model \(an AbstractFriction.*got NoneType"),
    (dict(friction=5), r"friction must be 'coulomb', .* or a friction model \(an AbstractFriction.*got int 5"),
])
def test_a_preset_given_a_part_of_the_wrong_kind_names_it(kwargs, match):
    with pytest.raises(PamjaxInputError, match=match):
        presets.mas10_system(**kwargs)
    if "valve" in kwargs:
        with pytest.raises(PamjaxInputError, match=match):
            presets.mas10_tank_system(**kwargs)


def test_a_silencer_sits_after_the_users_own_exhaust_port():
    """`mas10_valve(silencer=True, exhaust=port)`: the `exhaust` override replaced the silenced exhaust (the silencer
    dropped silently: 1.84x the silenced flow at 0.2 MPa); the silencer now follows the user's port."""
    import pamjax as pj

    port = pj.EllipseRestriction(0.39, 0.49, 3.14e-6)  # one's own fitted port (here Table 1's values)
    valve = presets.mas10_valve("smooth", silencer=True, exhaust=port)
    assert valve.exhaust.first is port
    assert float(valve.exhaust.second.permeance) == presets.MAS10_SILENCER_PERMEANCE
    silenced = presets.mas10_valve("smooth", silencer=True).exhaust
    air = pj.Air()
    assert float(valve.exhaust.mass_flow(2e5, 101325.0, air)) == pytest.approx(
        float(silenced.mass_flow(2e5, 101325.0, air)), rel=1e-9)
    assert presets.mas10_valve(exhaust=port).exhaust is port  # no silencer: the port as given


@pytest.mark.parametrize("call, match", [
    # each was Python's raw TypeError naming no valid field
    (lambda: presets.mas10_valve("smooth", switch_on_dely=3e-3),
     r"mas10_valve got the keyword switch_on_dely=, which is no OnOffValve field \(did you mean switch_on_delay=\?\)"
     r".*pwm_frequency, switch_on_delay, switch_off_delay"),
    (lambda: presets.mas10_valve("smooth", mode="exact"),
     r"mas10_valve got mode twice: 'smooth' \(positionally\) and mode='exact'; give it once"),
    (lambda: __import__("pamjax").vppm_regulator("fast", time_constant=(0.1, 0.2)),
     r"vppm_regulator got the keyword time_constant=, which is no ISO6358Regulator field \(did you mean "
     r"time_constants=\?\).*supply_pressure"),
    (lambda: presets.paper001_restriction("7e-4"),
     r"paper001_restriction: sonic_conductance_m3_per_s_bar must be a number \[m³/\(s bar\)\].*got '7e-4'"),
    # these were raw errors: jnp.asarray's ValueError of None, an unhashable list's TypeError
    (lambda: presets.paper001_restriction(None), r"sonic_conductance_m3_per_s_bar must be a number.*got None"),
    (lambda: presets.paper001_restriction(7e-4, None), r"critical_ratio must be a number in \(0, 1\).*got None"),
    (lambda: __import__("pamjax").vppm_regulator(["fast"]), r"mode must be one of .*got \['fast'\]"),
    # paper 001's C typed as its SI value into the argument in m³/(s bar): a flow 1e5 times too small, silently
    (lambda: presets.paper001_restriction(7.0564e-9, 0.5328), r"7.0564e-14 m³/\(s Pa\): less than 1e-12"),
])
def test_a_misspelt_or_doubled_preset_keyword_is_named_with_the_valid_fields(call, match):
    with pytest.raises(PamjaxInputError, match=match):
        call()


def test_a_preset_valves_mode_is_taken_positionally_or_as_a_keyword():
    assert presets.mas10_valve("exact").mode == "exact" and presets.mas10_valve(mode="exact").mode == "exact"
    assert presets.mas10_valve().mode == "smooth"


def test_saving_a_preset_holding_ones_own_component_says_how(tmp_path):
    """save_model of a model with a user's own class said only "... is not a pamjax model class", without the
    `classes=[...]` that both save_model and load_model take."""
    import pamjax as pj

    class MyFriction(pj.CoulombViscousFriction):
        pass

    system = presets.mas10_system(valve="averaged", friction=MyFriction(16.0, 250.0))
    with pytest.raises(PamjaxInputError, match=r"is not a pamjax model class \(pass your own component classes as "
                                               r"classes=\[\.\.\.\]\)"):
        pj.save_model(tmp_path / "m.json", system)


def test_paper_001s_tables_are_read_only():
    # presets exported the module's own dicts: an in-place "conversion" of a copy changed every later regulator
    with pytest.raises(TypeError):
        presets.PAPER001_CHARGING_TABLE["sonic_conductance_m3_per_s_bar"] = (1.0,)
    with pytest.raises(TypeError):
        presets.PAPER001_DISCHARGING_TABLE["critical_ratio"] = (0.5,)
