"""Units in model files come from the fields' metadata (`pamjax._core.fitting`: `positive(16.0, unit="N")`,
`parameter(..., unit=...)`), declared where the field is, never parsed out of source comments (issue 31): a class
whose source cannot be read (defined at run time, or shipped without its .py) still writes its units, and a comment
alone gives none."""

import dataclasses
import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._core.fitting import field_units, parameter, polynomial, positive, ratio


class Plate(eqx.Module):
    """A test component: units in metadata only."""

    area: jax.Array = positive(2.0, unit="m²")
    angle: jax.Array = parameter(0.1, unit="rad")
    share: jax.Array = ratio(0.5)
    width: jax.Array = eqx.field(converter=jnp.asarray, default=1.0)  # m   (a comment is not a unit)


def test_units_come_from_metadata_not_comments(tmp_path):
    assert field_units(Plate) == {"area": "m²", "angle": "rad", "share": "-"}
    doc = json.loads(pamjax.save_model(tmp_path / "plate.json", Plate(), classes=[Plate]).read_text())
    assert {k: v["unit"] for k, v in doc["parameters"].items()} == {"area": "m²", "angle": "rad", "share": "-",
                                                                     "width": ""}
    local = type("Local", (eqx.Module,), {"__annotations__": {"span": jax.Array}, "span": positive(3.0, unit="m")})
    doc = json.loads(pamjax.save_model(tmp_path / "local.json", local(), classes=[local]).read_text())  # no source
    assert doc["parameters"]["span"]["unit"] == "m"


@pytest.mark.parametrize("cls, field, unit", [
    (pamjax.OnOffValve, "supply_pressure", "Pa abs"), (pamjax.PolynomialForce, "max_force_coefficients", "N/m^i"),
    (pamjax.EllipseRestriction, "critical_ratio", "-"), (pamjax.AveragedValve, "coefficients", "kg/(s Pa^j)"),
    (pamjax.CoulombViscousFriction, "velocity_width", "m/s"), (pamjax.VoltageCalibration, "gauge_pressure", "Pa"),
    (pamjax.PIDController, "derivative_gain", "s/m"), (pamjax.Air, "atmospheric_pressure", "Pa abs"),
])
def test_components_declare_their_units(cls, field, unit):
    assert field_units(cls)[field] == unit


def test_metadata_helpers_keep_their_fit_metadata(tmp_path):
    assert polynomial("a{i}", "stroke", "N")["transform"] == "nodes"
    fields = {f.name: f.metadata for f in dataclasses.fields(Plate)}
    assert fields["area"]["transform"] == "log" and fields["share"]["bounds"] == (0.0, 1.0)
    assert "transform" not in fields["angle"]
    doc = json.loads(pamjax.save_model(tmp_path / "m.json", presets.mas10_system("pwm")).read_text())
    assert all(e["unit"] for e in doc["parameters"].values())


@pytest.mark.parametrize("path, bounds", [
    ("valve.inflate.discharge_coefficient", "FLOW_COEFFICIENT_RANGE"), ("polytropic_index", "POLYTROPIC_RANGE"),
    ("air.heat_capacity_ratio", "HEAT_CAPACITY_RATIO_RANGE"), ("muscle.slack_width", None),
    ("end_stops.width", "MAX_END_STOP_WIDTH"), ("gravity", None),
])
def test_a_default_transform_keeps_every_trial_value_in_the_range_its_component_accepts(path, bounds):
    # C_v was fitted in log space and converged at 1.105, the polytropic index linearly at 1.527 (the systems accept
    # (0.99, 1.41)), widths and gravity linearly through 0: fitted models `simulate`, `save_model` and `load_model`
    # refused. The logistic's bounds are the component's own constants.
    import numpy as np

    from pamjax._files.model_file import checked
    from pamjax._physics import gas, muscle

    model = presets.mas10_system("pwm")
    space = pamjax.ParameterSpace(model, [path])
    group = space.groups[0]
    if bounds is None:
        assert group.transform == "log"
    else:
        assert group.transform == "logistic"
        expected = (0.0, muscle.MAX_END_STOP_WIDTH) if bounds == "MAX_END_STOP_WIDTH" else getattr(gas, bounds)
        assert (float(group.lower[0]), float(group.upper[0])) == expected
    theta0 = float(np.asarray(space.initial_theta())[0])
    for step in (-20.0, -3.0, -1.0, 1.0, 3.0, 20.0):  # far out: an at-bound fit stops near |θ| = 15-20
        checked(space.model(np.array([theta0 + step])), "fitted")  # the component's own checks


def test_a_parameter_set_to_a_python_number_is_named_as_such_in_the_unknown_parameter_error():
    # eqx.tree_at(..., model, 6.0e5) leaves a Python float: not an array, so no parameter; the error only said
    # "unknown parameter" (the same path as an array is a parameter, and its fit is accepted)
    tank = presets.mas10_tank_system("pwm")
    t = np.linspace(0.0, 0.1, 11)
    exp = pamjax.Experiment(pamjax.Recording(t, {"pressure": np.full(11, 2e5)}), pamjax.Constant(1.0),
                            channels=["pressure"], scales=dict(pressure=2e3))
    number = eqx.tree_at(lambda m: m.valve.supply_pressure, tank, 6.0e5)
    assert "valve.supply_pressure" not in pamjax.parameter_paths(number)
    with pytest.raises(pamjax.PamjaxInputError, match=r"unknown parameter 'valve\.supply_pressure': it holds a "
                                                      r"Python number \(600000\.0\), not an array.*np\.asarray"):
        pamjax.fit(number, [exp], ["valve.supply_pressure"], progress=False)
    with pytest.raises(pamjax.PamjaxInputError, match=r"unknown parameter 'valve\.supply_pressur';"):  # a typo
        pamjax.ParameterSpace(tank, ["valve.supply_pressur"])
    fixed = eqx.tree_at(lambda m: m.valve.supply_pressure, tank, np.asarray(6.0e5))  # as the message says
    assert pamjax.ParameterSpace(fixed, ["valve.supply_pressure"]).labels == ["valve.supply_pressure"]
