"""Units in model files come from the fields' metadata (`pamjax._core.fitting`: `positive(16.0, unit="N")`,
`parameter(..., unit=...)`), declared where the field is, never parsed out of source comments (issue 31): a class
whose source cannot be read (defined at run time, or shipped without its .py) still writes its units, and a comment
alone gives none."""

import dataclasses
import json

import equinox as eqx
import jax
import jax.numpy as jnp
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
