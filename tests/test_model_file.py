"""Model files (`pamjax.save_model` / `pamjax.load_model`, `pamjax._files.model_file`): every model pamjax builds is
written whole (every parameter with its unit, the structure, the static settings) and read back equal, bitwise; a
damaged or hand-edited file is refused naming the file and the entry, and a file cannot make pamjax run code."""

import json
import pathlib

import equinox as eqx
import jax.numpy as jnp
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
     r"m\.json: parameter valve\.supply_pressure .*looks like bar"),
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
    # a number in quotes was read as the number (any text through float()): only nan/inf are written quoted
    (lambda d: d["parameters"]["payload_mass"].update(value="9.6"),
     r"parameter 'payload_mass': '9.6' is not a number .*'9.6' is text: write a number without quotes"),
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
    swapped = tmp_path / "swapped.json"
    with pytest.raises(PamjaxInputError, match=r"save_model takes the path first: save_model\('.*swapped\.json', "):
        pamjax.save_model(presets.mas10_system("pwm"), str(swapped))  # the arguments swapped: named, nothing written
    assert not swapped.exists()


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


# -- hand-edited files: units, magnitudes, dtypes, shapes, duplicated keys (issue 33) ------------------------------
def _file(tmp_path, edit, model=None, text=None):
    """A saved model file with `edit(parameters)` applied (or with its text passed through `text`)."""
    model = presets.mas10_system("averaged", friction="karnopp") if model is None else model
    path = pamjax.save_model(tmp_path / "m.json", model, overwrite=True)
    doc = json.loads(path.read_text(encoding="utf-8"))
    edit(doc["parameters"])
    body = json.dumps(doc, indent=1, ensure_ascii=False)
    path.write_text(text(body) if text else body, encoding="utf-8")
    return path


@pytest.mark.parametrize("path, value, unit, si", [
    ("payload_mass", 9600.0, "g", 9.6),
    ("muscle.volume_law.v0", 23.1, "cm³", 23.1e-6),
    ("muscle.volume_law.v0", 23.1, "cm^3", 23.1e-6),
    ("air.atmospheric_pressure", 1.01325, "bar abs", 101325.0),
    ("air.atmospheric_pressure", 0.0, "bar gauge", 101325.0),
    ("air.temperature", 20.0, "°C", 293.15),
    ("muscle.min_position", -20.0, "mm", -0.02),
    ("muscle.force_law.max_pressure", 6.0, "bar gauge", 6e5),
    ("muscle.force_law.max_pressure", 701325.0, "Pa abs", 6e5),
    ("muscle.force_law.k2", 1.0, "bar", 1e5),
])
def test_a_value_in_another_unit_is_converted_to_si(tmp_path, path, value, unit, si):
    # the file's unit is honoured: the loaded model holds the SI value, as if it had been written in SI
    m = pamjax.load_model(_file(tmp_path, lambda p: p[path].update(value=value, unit=unit)))
    leaf = m
    for attr in path.split("."):
        leaf = getattr(leaf, attr)
    assert float(leaf) == pytest.approx(si, rel=1e-12, abs=1e-12)


def test_a_gauge_unit_is_relative_to_the_models_own_atmosphere(tmp_path):
    # a bench at 1,600 m (83.4 kPa): "6 bar gauge" was read as 6e5 + 101325 Pa whatever the file's atmosphere, 17.9 kPa
    # too high; p_max in "Pa abs" likewise 17.9 kPa too low
    def edit(p):
        p["air.atmospheric_pressure"].update(value=83.4, unit="kPa abs")
        p["valve.supply_pressure"].update(value=6.0, unit="bar gauge")
        p["muscle.force_law.max_pressure"].update(value=683400.0, unit="Pa abs")

    m = pamjax.load_model(_file(tmp_path, edit, model=presets.mas10_system("pwm")))
    assert float(m.air.atmospheric_pressure) == pytest.approx(83400.0, rel=1e-12)
    assert float(m.valve.supply_pressure) == pytest.approx(683400.0, rel=1e-12)
    assert float(m.muscle.force_law.max_pressure) == pytest.approx(6e5, rel=1e-12)


@pytest.mark.parametrize("path, value, unit, match", [
    # the battery's silent cases: a number in another unit under the SI one
    ("payload_mass", 9600.0, "kg", r"m\.json: parameter payload_mass = 9600 kg.*looks like g.*\"unit\": \"g\""),
    ("muscle.volume_law.v0", 23.1, "m³", r"m\.json: parameter muscle\.volume_law\.v0 = 23\.1.*looks like cm³"),
    ("air.atmospheric_pressure", 1.01325, "Pa abs",
     r"m\.json: parameter air\.atmospheric_pressure .*looks like bar.*\"unit\": \"bar abs\""),
    ("air.temperature", 20.0, "K", r"m\.json: parameter air\.temperature = 20 K.*looks like °C.*\"unit\": \"°C\""),
    # units that cannot be converted, or that leave absolute/gauge open, are refused by name
    ("payload_mass", 21.0, "lb", r"m\.json: parameter 'payload_mass': unit 'lb' is not one pamjax converts.*'g'"),
    ("payload_mass", 9.6, "N", r"parameter 'payload_mass': unit 'N'"),
    ("air.atmospheric_pressure", 1.01325, "bar", r"'air\.atmospheric_pressure': unit 'bar': say whether"),
    ("muscle.force_law.max_pressure", 6e5, "Pa", r"'muscle\.force_law\.max_pressure': unit 'Pa': say whether"),
    ("muscle.force_law.k2", 1.0, "bar abs", r"'muscle\.force_law\.k2': unit 'bar abs' says absolute or gauge"),
])
def test_a_value_whose_unit_is_wrong_or_unknown_is_refused_naming_parameter_and_file(tmp_path, path, value, unit,
                                                                                      match):
    with pytest.raises(PamjaxInputError, match=match):
        pamjax.load_model(_file(tmp_path, lambda p: p[path].update(value=value, unit=unit)))


def test_the_suggested_unit_loads_the_intended_model(tmp_path):
    # "if the number is right in g, say so in its entry ("unit": "g")": doing so gives the 9.6 kg model
    with pytest.raises(PamjaxInputError, match=r'"unit": "g"'):
        pamjax.load_model(_file(tmp_path, lambda p: p["payload_mass"].update(value=9600.0)))
    model = pamjax.load_model(_file(tmp_path, lambda p: p["payload_mass"].update(value=9600.0, unit="g")))
    assert eqx.tree_equal(model, presets.mas10_system("averaged", friction="karnopp"))


@pytest.mark.parametrize("dtype, match", [
    ("int8", r"'payload_mass': dtype 'int8': a model parameter is a floating-point number"),
    ("bool", r"dtype 'bool'"),
    ("float16", None),  # 9.6 is not a float16: refused as lossy
    ("complex128", r"dtype 'complex128'"),
    ("quad", r"dtype 'quad' is not a dtype"),
])
def test_a_dtype_that_would_change_the_value_is_refused(tmp_path, dtype, match):
    with pytest.raises(PamjaxInputError, match=match or r"dtype 'float16' cannot hold 9\.6"):
        pamjax.load_model(_file(tmp_path, lambda p: p["payload_mass"].update(dtype=dtype)))


def test_a_float32_model_round_trips_and_a_float32_edit_is_rounded_only(tmp_path):
    model = eqx.tree_at(lambda s: s.payload_mass, presets.mas10_system("averaged"), np.float32(9.6))
    back = pamjax.load_model(pamjax.save_model(tmp_path / "f32.json", model))
    _assert_identical(model, back)
    edited = pamjax.load_model(_file(tmp_path, lambda p: p["payload_mass"].update(dtype="float32")))
    assert edited.payload_mass.dtype == np.float32 and float(edited.payload_mass) == pytest.approx(9.6, rel=1e-7)


def test_a_duplicated_key_is_refused_with_its_lines(tmp_path):
    # JSON keeps the last of two keys silently: 96 kg instead of 9.6 kg
    path = _file(tmp_path, lambda p: None, text=lambda body: body.replace(
        '"payload_mass": {', '"payload_mass": {"value": 96.0, "unit": "kg"},\n  "payload_mass": {', 1))
    with pytest.raises(PamjaxInputError, match=r"m\.json: key 'payload_mass' appears twice in one table \(lines "
                                               r"\d+, \d+\)"):
        pamjax.load_model(path)


@pytest.mark.parametrize("value", [[9.6, 9.6], [[9.6]]])
def test_a_parameter_holding_several_values_is_refused_on_load_and_save(tmp_path, value):
    # it loaded, and simulate failed with "scan body function carry input and carry output must have equal types"
    with pytest.raises(PamjaxInputError, match=r"m\.json: parameter 'payload_mass' has shape \([\d, ]+\) where the "
                                               "model takes one number"):
        pamjax.load_model(_file(tmp_path, lambda p: p["payload_mass"].update(value=value)))
    batch = eqx.tree_at(lambda s: s.payload_mass, presets.mas10_system("averaged"), jnp.asarray(value))
    with pytest.raises(PamjaxInputError, match=r"cannot save .*b\.json: parameter 'payload_mass'"):
        pamjax.save_model(tmp_path / "b.json", batch)
    assert not (tmp_path / "b.json").exists()


def test_save_refuses_what_load_would_refuse(tmp_path):
    # a NaN friction force set with eqx.tree_at (no constructor check) was written, and the file then refused
    bad = eqx.tree_at(lambda s: s.friction.coulomb_force, presets.mas10_system("averaged"), jnp.asarray(np.nan))
    with pytest.raises(PamjaxInputError, match=r"cannot save .*m\.json: friction .*coulomb_force must be"):
        pamjax.save_model(tmp_path / "m.json", bad)
    grams = eqx.tree_at(lambda s: s.payload_mass, presets.mas10_system("averaged"), jnp.asarray(9600.0))
    with pytest.raises(PamjaxInputError, match=r"payload_mass = 9600 kg.*looks like g"):
        pamjax.save_model(tmp_path / "m.json", grams)
    assert not (tmp_path / "m.json").exists()


def test_a_closed_loop_with_its_default_estimator_round_trips(tmp_path):
    # the estimator's spreads per state (initial_std, process_noise: Pa and Pa/√s for the pressure) are not absolute
    # pressures, and the sensors' seed is an integer: both were refused by save_model before
    model = presets.mas10_system("averaged")
    loop = pamjax.ClosedLoop(presets.mas10_system("pwm"), pamjax.SlidingModeController(model), pamjax.Constant(0.03),
                             estimator=pamjax.ExtendedKalmanFilter(model), sensors=pamjax.LoopSensors(seed=7))
    path = pamjax.save_model(tmp_path / "loop.json", loop)
    back = pamjax.load_model(path)
    _assert_identical(loop, back)
    assert int(back.sensors.seed) == 7 and back.sensors.seed.dtype == loop.sensors.seed.dtype
    doc = json.loads(path.read_text(encoding="utf-8"))
    doc["parameters"]["sensors.seed"]["value"] = 7.5  # a seed must stay a whole number
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(PamjaxInputError, match=r"'sensors.seed': dtype 'int32' cannot hold 7\.5"):
        pamjax.load_model(path)


def test_a_signal_is_not_saved_as_a_model(tmp_path):
    with pytest.raises(PamjaxInputError, match=r"got the signal Triangle: a signal is an input"):
        pamjax.save_model(tmp_path / "s.json", pamjax.Triangle(0.05, 0.95, 0.25))


def test_simulate_writes_the_columns_in_the_documented_order():
    # docs/cli.md: t, command, pressure, position, velocity, force, friction_force, mass_flow, volume
    from pamjax._cli.simulate import columns_of

    traj = pamjax.simulate(presets.mas10_system("averaged"), pamjax.Constant(0.5), jnp.linspace(0.0, 0.05, 3))
    cols, units = columns_of(traj)
    assert list(cols) == ["t", "command", "pressure", "position", "velocity", "force", "friction_force", "mass_flow",
                          "volume"]
    assert units["pressure"] == "Pa abs"


def test_a_closed_loops_period_is_saved_with_its_unit(tmp_path):
    # ClosedLoop.period was declared with a comment only (`# s`): its entry had no unit
    loop = pamjax.ClosedLoop(presets.mas10_system("pwm"), pamjax.PIController(), pamjax.Constant(0.03))
    path = pamjax.save_model(tmp_path / "loop.json", loop)
    entry = json.loads(path.read_text(encoding="utf-8"))["parameters"]["period"]
    assert entry["unit"] == "s" and entry["value"] == 0.02
    _assert_identical(loop, pamjax.load_model(path))


# -- empty values, malformed structure, provenance; fit.json beside it ---------------------------------------------
@pytest.mark.parametrize("path", ["payload_mass", "friction.coulomb_force"])
def test_an_empty_value_is_refused_on_load_and_save(tmp_path, path):
    # "value": [] loaded as shape (0,), and simulate then failed with a raw JAX TypeError about its scan's carry
    with pytest.raises(PamjaxInputError, match=rf"m\.json: parameter '{path}': \[\] holds no number; write its value"):
        pamjax.load_model(_file(tmp_path, lambda p: p[path].update(value=[])))
    empty = eqx.tree_at(lambda s: s.payload_mass, presets.mas10_system("averaged"), jnp.zeros((0,)))
    with pytest.raises(PamjaxInputError, match=r"cannot save .*e\.json: parameter 'payload_mass': \[\] holds no"):
        pamjax.save_model(tmp_path / "e.json", empty)
    assert not (tmp_path / "e.json").exists()


@pytest.mark.parametrize("edit, match", [
    (lambda d: d.pop("parameters"), r"m\.json: no 'parameters' table"),  # was a KeyError
    (lambda d: d["structure"].update({"class": 5}), r"m\.json: structure at the top: \"class\" must be a class name"),
    (lambda d: d["structure"].update({"fields": []}), r"m\.json: MuscleSystem at the top: \"fields\" must be a table"),
    (lambda d: d["structure"]["fields"].update(payload_mass={"array": ["payload_mass"]}),
     r"m\.json: structure at payload_mass: \"array\" must name a parameter"),
    (lambda d: d["structure"]["fields"]["valve"]["fields"].update(mode={"tuple": 3}),
     r"m\.json: structure at valve\.mode: \"tuple\" must be a list"),
    # a top-level "class" contradicting the structure was ignored (the file said one model and loaded another)
    (lambda d: d.update({"class": "TankSystem"}),
     r"m\.json: its \"class\" is 'TankSystem', but its structure builds a MuscleSystem"),
])
def test_a_malformed_structure_is_refused_naming_the_entry(tmp_path, edit, match):
    # each escaped as a raw KeyError, TypeError or AttributeError
    with pytest.raises(PamjaxInputError, match=match):
        pamjax.load_model(_edited(tmp_path, edit))


def test_provenance_is_stored_as_strict_json_or_refused_by_name(tmp_path):
    # inf and NumPy scalars (a FitResult's to_dict(), a count from NumPy) raised raw JSON errors
    model = presets.mas10_system("averaged")
    provenance = {"se": [float("inf"), np.float32(1.5)], "n": np.int64(3), "values": np.array([1.0, 2.0])}
    path = pamjax.save_model(tmp_path / "p.json", model, provenance=provenance)
    assert json.loads(path.read_text(encoding="utf-8"))["provenance"] == {"se": ["inf", 1.5], "n": 3,
                                                                          "values": [1.0, 2.0]}
    _assert_identical(model, pamjax.load_model(path))
    with pytest.raises(PamjaxInputError, match=r"provenance must hold numbers, text, lists and dicts only"):
        pamjax.save_model(tmp_path / "q.json", model, provenance={"when": object()})
    with pytest.raises(PamjaxInputError, match=r"provenance must be a dict"):
        pamjax.save_model(tmp_path / "q.json", model, provenance=["fit"])
    assert not (tmp_path / "q.json").exists()


def _fit_result():
    """A small FitResult made by hand (no fit): what to_json / from_json move."""
    return pamjax.FitResult(
        labels=["payload_mass"], paths=["payload_mass"], values=[9.6], initial_values=[9.0],
        standard_errors=[float("inf")], correlation=[[1.0]], cost=1.0, initial_cost=2.0, iterations=3,
        accepted_steps=2, status="converged", converged=True, message="converged", channel_errors={}, mismatch=False,
        non_identifiable=[["payload_mass"]], warnings=[], history=[], fit_s=0.1, compile_s=0.2, num_residuals=10)


def test_fit_result_json_names_a_model_file_and_is_replaced_whole(tmp_path, monkeypatch):
    # from_json of a model.json raised a raw TypeError about `format`; to_json wrote in place, so a crash while
    # overwriting truncated the previous fit.json
    model_path = pamjax.save_model(tmp_path / "model.json", presets.mas10_system("averaged"))
    with pytest.raises(PamjaxInputError, match=r"model\.json: not a fit result \(fit\.json\): a model file .*load_"):
        pamjax.FitResult.from_json(model_path)
    (tmp_path / "other.json").write_text('{"labels": []}')
    with pytest.raises(PamjaxInputError, match=r"other\.json: not a fit result .*missing"):
        pamjax.FitResult.from_json(tmp_path / "other.json")
    result = _fit_result()
    path = result.to_json(tmp_path / "fit.json")
    assert pamjax.FitResult.from_json(path) == result
    before = path.read_text()
    real = pathlib.Path.write_text

    def crash(self, text, *args, **kwargs):  # half the file written, then the process dies
        real(self, text[: len(text) // 2], *args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(pathlib.Path, "write_text", crash)
    with pytest.raises(KeyboardInterrupt):
        result.to_json(path, overwrite=True)
    monkeypatch.undo()
    assert path.read_text() == before and sorted(p.name for p in tmp_path.iterdir()) == ["fit.json", "model.json",
                                                                                        "other.json"]


def _drop_payload(d):
    del d["parameters"]["payload_mass"], d["structure"]["fields"]["payload_mass"]


def _inflate(d):
    return d["structure"]["fields"]["valve"]["fields"]["inflate"]["fields"]


@pytest.mark.parametrize("edit, match", [
    # removed from both tables, it loaded silently with the class default (a fitted 20 kg payload read as 9.6 kg)
    (_drop_payload, r"m\.json: MuscleSystem: parameter 'payload_mass' is missing from the file; the class default "
                    r"is not filled in"),
    (lambda d: _inflate(d).pop("laminar_ratio"), r"m\.json: valve\.inflate \(EllipseRestriction\): setting "
                                                 r"'valve\.inflate\.laminar_ratio' is missing"),
    # a float setting in quotes raised numpy's TypeError in the constructor's checks, taken for "a constructor with
    # its own signature": the component was rebuilt field by field without its checks, and simulate failed raw
    (lambda d: _inflate(d).update(laminar_ratio={"value": "0.999"}),
     r"m\.json: structure at valve\.inflate\.laminar_ratio \(EllipseRestriction\.laminar_ratio\): \"0\.999\" is not "
     r"a number .*write a number without quotes"),
    (lambda d: _inflate(d).update(laminar_ratio={"value": True}), r"laminar_ratio\): true is not a number"),
    # a parameter written as a setting: a raw ValueError from jnp.array
    (lambda d: (d["parameters"].pop("gravity"), d["structure"]["fields"].update(gravity={"value": None})),
     r"m\.json: structure at gravity \(MuscleSystem\.gravity\): null is written as a setting, but gravity is a "
     r"parameter: write \{\"array\": \"gravity\"\}"),
])
def test_a_missing_field_or_a_setting_of_the_wrong_kind_is_refused_naming_the_entry(tmp_path, edit, match):
    with pytest.raises(PamjaxInputError, match=match):
        pamjax.load_model(_edited(tmp_path, edit))


def test_a_model_file_with_a_byte_order_mark_loads_and_a_folder_is_not_overwritten(tmp_path):
    # Notepad's "UTF-8 with BOM" (CRLF): "line 1, column 1: not valid JSON: Expecting value"
    path = _edited(tmp_path, lambda d: None)
    model = pamjax.load_model(path)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_text(encoding="utf-8").replace("\n", "\r\n").encode("utf-8"))
    assert eqx.tree_equal(pamjax.load_model(path), model)
    (tmp_path / "folder.json").mkdir()  # was a raw IsADirectoryError from the rename over it
    with pytest.raises(PamjaxInputError, match=r"save_model: .*folder\.json is a folder; give the model file's path"):
        pamjax.save_model(tmp_path / "folder.json", model, overwrite=True)


def test_a_python_float_set_with_tree_at_is_saved_as_the_parameter(tmp_path):
    # eqx.tree_at(..., 20.0) simulates, but save_model refused it with advice about editing the JSON file
    model = eqx.tree_at(lambda s: s.payload_mass, presets.mas10_system("pwm"), 20.0)
    back = pamjax.load_model(pamjax.save_model(tmp_path / "m.json", model))
    assert eqx.is_array(back.payload_mass) and back.payload_mass.dtype == jnp.float64
    assert float(back.payload_mass) == 20.0


@pytest.mark.parametrize("node, edit, unknown", [
    ("payload_mass", {"unit": "g"}, "unit"),  # a unit beside {"array": ...} had no effect
    ("friction", {"klass": "KarnoppFriction"}, "klass"),  # a misspelt key beside "class" was ignored
])
def test_unknown_keys_in_a_structure_node_are_refused_by_name(tmp_path, node, edit, unknown):
    path = pamjax.save_model(tmp_path / "m.json", presets.mas10_system("pwm"))
    d = json.loads(path.read_text())
    d["structure"]["fields"][node].update(edit)
    path.write_text(json.dumps(d))
    with pytest.raises(PamjaxInputError, match=rf"structure at {node} has unknown key\(s\) \['{unknown}'\]"):
        pamjax.load_model(path)


def test_a_joint_file_with_several_values_in_a_scalar_parameter_is_refused(tmp_path):
    # the shape inference ran with a scalar command, which the joint refuses: nothing was found
    joint = pamjax.AntagonisticJoint(pamjax.vppm_regulator(), pamjax.vppm_regulator(), presets.dmsp40_muscle(),
                                     presets.dmsp40_muscle())
    path = pamjax.save_model(tmp_path / "joint.json", joint)
    d = json.loads(path.read_text())
    d["parameters"]["inertia"]["value"] = [0.05, 0.05]
    path.write_text(json.dumps(d))
    with pytest.raises(PamjaxInputError, match=r"'inertia' has shape \(2,\) where the model takes one number"):
        pamjax.load_model(path)
