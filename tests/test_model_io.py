"""Model files (`pamjax.save_model` / `pamjax.load_model`, `pamjax._model_io`): every model pamjax builds is written
whole (every parameter with its unit, the structure, the static settings) and read back equal, bitwise; a damaged or
hand-edited file is refused naming the file and the entry, and a file cannot make pamjax run code."""

import json

import equinox as eqx
import jax.tree_util as jtu
import numpy as np
import pytest

import pamjax
from pamjax import PamjaxInputError, presets

MODELS = {
    "MAS-10, smoothed PWM valve": lambda: presets.mas10_system("pwm"),
    "MAS-10, exact-edge valve, bristle friction": lambda: presets.mas10_system("exact", friction="bristle"),
    "MAS-10, averaged valve": lambda: presets.mas10_system("averaged"),
    "tank test": lambda: presets.mas10_tank_system("pwm"),
    "DMSP-40 muscle alone": presets.dmsp40_muscle,
    "regulator-fed muscle": lambda: pamjax.RegulatedMuscleSystem(pamjax.ISO6358Regulator(), presets.dmsp40_muscle(),
                                                                 load_force=893.0),
}


def _assert_identical(a, b):
    (la, ta), (lb, tb) = jtu.tree_flatten(a), jtu.tree_flatten(b)
    assert ta == tb  # classes, fields and static settings (e.g. the valve's mode)
    for x, y in zip(la, lb):
        assert np.asarray(x).dtype == np.asarray(y).dtype and np.shape(x) == np.shape(y)
        np.testing.assert_array_equal(x, y)  # bitwise (floats are written with repr)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_every_model_round_trips_bitwise_with_every_parameter_and_unit(tmp_path, name):
    model = MODELS[name]()
    path = pamjax.save_model(tmp_path / "model.json", model, provenance={"by": "test"})
    back = pamjax.load_model(path)
    _assert_identical(model, back)
    assert eqx.tree_equal(model, back)
    doc = json.loads(path.read_text(encoding="utf-8"))
    assert set(doc["parameters"]) == set(pamjax.parameter_paths(model))  # every parameter, by its fit path
    no_unit = [p for p, e in doc["parameters"].items() if not e["unit"]]
    assert not no_unit, f"parameters without a unit: {no_unit}"
    assert doc["provenance"] == {"by": "test"} and doc["class"] == type(model).__name__


def test_a_changed_value_changes_the_model(tmp_path):
    # the comparison above can fail: a model with one value changed is not read back equal to the original
    model = presets.mas10_system("averaged")
    path = pamjax.save_model(tmp_path / "m.json", model)
    doc = json.loads(path.read_text(encoding="utf-8"))
    doc["parameters"]["friction.coulomb_force"]["value"] = 20.0
    path.write_text(json.dumps(doc), encoding="utf-8")
    back = pamjax.load_model(path)
    assert float(back.friction.coulomb_force) == 20.0 and not eqx.tree_equal(model, back)


def _edited(tmp_path, edit):
    path = pamjax.save_model(tmp_path / "m.json", presets.mas10_system("pwm"), overwrite=True)
    doc = json.loads(path.read_text(encoding="utf-8"))
    edit(doc)
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


@pytest.mark.parametrize("edit, match", [
    (lambda d: d["parameters"]["payload_mass"].update(value=-1.0),
     r"m\.json: MuscleSystem: .*payload_mass must be > 0"),
    (lambda d: d["parameters"]["valve.supply_pressure"].update(value=6.5),
     r"m\.json: valve \(OnOffValve\): .*supply_pressure"),
    (lambda d: d["parameters"].pop("friction.coulomb_force"), r"'friction\.coulomb_force' is missing"),
    (lambda d: d["parameters"].update({"friction.coulomb": {"value": 1.0, "unit": "N"}}),
     r"\['friction\.coulomb'\] are not part of the model's structure"),
    (lambda d: d["structure"]["fields"]["friction"].update({"class": "os.system"}),
     r"class 'os\.system' at friction is not a pamjax model class"),
    (lambda d: d["structure"]["fields"]["valve"]["fields"].update(modes={"value": "exact"}),
     r"OnOffValve at valve has no field\(s\) \['modes'\]"),
    (lambda d: d["structure"]["fields"]["valve"]["fields"]["mode"].update(value="fast"), r"mode"),
    (lambda d: d.update(format="something else"), r"is not a pamjax model file"),
    (lambda d: d.update(format_version=99), r"format_version 99"),
])
def test_a_damaged_file_is_refused_naming_the_entry(tmp_path, edit, match):
    with pytest.raises(PamjaxInputError, match=match):
        pamjax.load_model(_edited(tmp_path, edit))


def test_bad_json_names_line_and_column_and_files_are_never_replaced(tmp_path):
    path = tmp_path / "m.json"
    path.write_text('{\n "format": "pamjax-model",\n "format_version": 1,,\n}\n')
    with pytest.raises(PamjaxInputError, match=r"m\.json, line 3, column 22: not valid JSON"):
        pamjax.load_model(path)
    with pytest.raises(PamjaxInputError, match="does not exist"):
        pamjax.load_model(tmp_path / "missing.json")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        pamjax.save_model(path, presets.mas10_system("pwm"))


def test_a_fitted_model_carries_on(tmp_path):
    # FitResult.model is what `pamjax fit` writes; simulating the loaded model gives the same trajectory, bitwise
    import jax.numpy as jnp

    model = presets.mas10_system("averaged")
    space = pamjax.ParameterSpace(model, ["friction.coulomb_force", "muscle.volume_law.v0"])
    fitted = space.with_values(np.asarray(space.initial_values()) * 1.1)  # what fit's with_values makes
    back = pamjax.load_model(pamjax.save_model(tmp_path / "fitted.json", fitted))
    _assert_identical(fitted, back)
    ts = jnp.linspace(0.0, 0.5, 11)
    a = pamjax.simulate(fitted, pamjax.Constant(0.5), ts)
    b = pamjax.simulate(back, pamjax.Constant(0.5), ts)
    np.testing.assert_array_equal(a.position, b.position)
