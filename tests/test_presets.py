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
