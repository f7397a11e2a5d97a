"""`fit` misuse of battery section 7 (issue 33), refused by name before any solve: free entries that move one
element twice, and fewer residuals than free parameters (which ended "converged" with a finite standard error from
m − n = −1). Also the fit API tester's misuse, refused before anything compiles, in the modules `fit` reads its
inputs through: `_fit/experiment.py` (a channel named twice, counts), `_fit/parameters.py` (bounds with a transform
that ignores them, malformed free entries), `_fit/diagnostics.py` (`identifiability_tol`) and `_fit/staged.py`
(`staged_start` checks what `fit` checks, before its first stage)."""

import numpy as np
import pytest

import pamjax
from pamjax import PamjaxInputError, presets


@pytest.mark.parametrize("free", [["valve.coefficients", "valve.coefficients[1,0]"],
                                  ["valve.coefficients[1,0]", "valve.coefficients"]])
def test_free_entries_that_overlap_are_refused(free):
    # the whole array frees m4 too: it was fitted twice, with the warning "parameter m4 has no effect on the data"
    with pytest.raises(PamjaxInputError, match=r"free names valve\.coefficients\[1,0\] twice"):
        pamjax.ParameterSpace(presets.mas10_system("averaged"), free)
    assert pamjax.ParameterSpace(presets.mas10_system("averaged"),
                                 ["valve.coefficients[1,0]", "valve.coefficients[2,0]"]).labels  # disjoint: fine


def test_fewer_residuals_than_free_parameters_is_refused():
    model = presets.mas10_system("averaged")
    rec = pamjax.synthetic_recording(model, pamjax.Constant(0.5), np.array([0.0, 0.05]),
                                     noise=dict(pressure=2e3, position=1e-4), seed=0)
    exp = pamjax.Experiment(rec, pamjax.Constant(0.5), channels=["pressure", "position"],
                            scales=dict(pressure=2e3, position=1e-4))
    free = ["friction.coulomb_force", "muscle.volume_law.v0", "muscle.volume_law.v1", "muscle.force_law.k0",
            "friction.viscous_coefficient"]
    with pytest.raises(PamjaxInputError, match=r"give 4 residuals .* for 5 free parameters"):
        pamjax.fit(model, [exp], free, progress=False)


def test_max_steps_takes_a_numpy_integer_and_refuses_a_bool():
    # `fit(max_steps=np.int64(3))` was refused as "max_steps must be a positive int, got 3"
    from pamjax._fit.fit import _validate

    exp = pamjax.Experiment(pamjax.Recording(np.linspace(0.0, 0.1, 5), {"pressure": np.full(5, 2e5)}),
                            pamjax.Constant(0.5))
    assert _validate([exp], np.int64(3), None, False, None, None) == [exp]
    for bad in (True, 0, 2.5):
        with pytest.raises(PamjaxInputError, match=r"max_steps must be a positive int"):
            _validate([exp], bad, None, False, None, None)


# Misuse found by the fit API's tester (issue: fitapi), refused by name before anything compiles.

def _recording():
    return pamjax.Recording(np.linspace(0.0, 0.1, 5), {"pressure": np.full(5, 2e5)}, name="r")


def test_a_channel_named_twice_is_refused():
    # channels=["pressure", "pressure"] fitted every sample twice: the standard errors shrank by √2, with no warning
    with pytest.raises(PamjaxInputError, match=r"channels names 'pressure' more than once"):
        pamjax.Experiment(_recording(), pamjax.Constant(0.5), channels=["pressure", "pressure"])
    with pytest.raises(PamjaxInputError, match=r"channels must be a list of channel names"):
        pamjax.Experiment(_recording(), pamjax.Constant(0.5), channels="pressure")
    assert pamjax.Experiment(_recording(), pamjax.Constant(0.5), channels=["pressure"]).channels == ("pressure",)


@pytest.mark.parametrize("transform", ["linear", "log", "nodes"])
def test_bounds_with_a_transform_that_ignores_them_are_refused(transform):
    # "linear" and "log" ignored the bounds: the fit ended above the upper one and said converged
    model = presets.mas10_tank_system(valve="averaged")  # volume 5e-5
    with pytest.raises(PamjaxInputError, match=r"'volume': bounds apply through the 'logistic' transform, not "
                                               rf"'{transform}' .*drop transform or bounds"):
        pamjax.ParameterSpace(model, [{"path": "volume", "transform": transform, "bounds": (1e-5, 1e-4)}])
    for entry in ({"path": "volume", "bounds": (1e-5, 1e-4)},
                  {"path": "volume", "transform": "logistic", "bounds": (1e-5, 1e-4)}):
        assert pamjax.ParameterSpace(model, [entry]).groups[0].transform == "logistic"


@pytest.mark.parametrize("tol", [float("nan"), -1.0, 0.0, 1.0, 2.0, float("inf"), True, "1e-6", [1e-6]])
def test_identifiability_tol_outside_zero_one_is_refused(tol):
    # NaN gave standard errors of exactly 0 (every direction left out of the covariance) and no warning
    model = presets.mas10_tank_system(valve="averaged")
    exp = pamjax.Experiment(_recording(), pamjax.Constant(0.5))
    with pytest.raises(PamjaxInputError, match=r"identifiability_tol must be a number in \(0, 1\)"):
        pamjax.fit(model, [exp], ["volume"], identifiability_tol=tol, progress=False)


def test_identifiability_tol_takes_any_real_number_in_zero_one():
    from pamjax._fit.diagnostics import check_identifiability_tol

    for tol in (1e-6, np.float64(1e-7), np.float32(0.5), np.asarray(1e-3), 1e-12):
        assert check_identifiability_tol(tol) == float(tol)


def _staged_problem():
    model = presets.mas10_system(valve="pwm", friction="karnopp")
    rec = pamjax.Recording(np.linspace(0.0, 0.1, 5), {"pressure": np.full(5, 2e5), "position": np.zeros(5)})
    run = pamjax.Experiment(rec, pamjax.Constant(0.5), name="tri")
    tank = pamjax.Experiment(_recording(), pamjax.Constant(0.5), build=pamjax.TankFromModel(5e-5), name="tank")
    return model, run, tank


@pytest.mark.parametrize("case", ["misspelt path", "parameter twice", "experiment names twice", "not experiments"])
def test_staged_start_refuses_what_fit_refuses_before_any_stage(case, monkeypatch):
    # a misspelt path dropped out of the stages silently; names given twice were refused after a stage had compiled
    import pamjax._fit.staged as staged_module

    def no_stage(*args, **kwargs):
        raise AssertionError("a stage was fitted")

    monkeypatch.setattr(staged_module, "fit", no_stage)
    monkeypatch.setattr(staged_module, "precompile", no_stage)
    model, run, tank = _staged_problem()
    free = ["valve.inflate.discharge_coefficient", "muscle.volume_law.v0", "friction.coulomb_force"]
    exps, match = [run, tank], {"misspelt path": r"unknown parameter 'valve\.inflate\.discharge_coef'",
                                "parameter twice": r"named twice", "experiment names twice": r"names must be unique",
                                "not experiments": r"must be pamjax experiments"}[case]
    if case == "misspelt path":
        free[0] = "valve.inflate.discharge_coef"
    elif case == "parameter twice":
        free.append("muscle.volume_law.v0")
    elif case == "experiment names twice":
        exps = [run, run, tank]
    else:
        exps = [run, "tank"]
    with pytest.raises(PamjaxInputError, match=match):
        pamjax.staged_start(model, exps, free, max_steps=2, progress=False, background_compile=False)


def test_substeps_and_counts_take_numpy_integers_and_refuse_bools():
    # Experiment(substeps=np.int64(16)) was refused as "substeps must be an int >= 2"
    exp = pamjax.Experiment(_recording(), pamjax.Constant(0.5), substeps=np.int64(16), max_steps=np.int64(50))
    assert exp.substeps == 16 and type(exp.substeps) is int and exp.max_steps == 50
    for bad in (True, 1, 2.0, np.int64(1)):
        with pytest.raises(PamjaxInputError, match=r"substeps must be an int >= 2"):
            pamjax.Experiment(_recording(), pamjax.Constant(0.5), substeps=bad)
    for bad in (True, 0, 2.5):  # int(2.5) was 2, int(True) 1: taken silently
        with pytest.raises(PamjaxInputError, match=r"max_steps must be a positive int"):
            pamjax.Experiment(_recording(), pamjax.Constant(0.5), max_steps=bad)
    from pamjax._fit.fit import _check_settings

    assert _check_settings(1e-10, 1e-10, 1e-10, np.int64(8)) == 8  # fit(stall_steps=np.int64(8)) was refused
    for bad in (True, 0, 2.5):
        with pytest.raises(PamjaxInputError, match=r"stall_steps must be a positive int"):
            _check_settings(1e-10, 1e-10, 1e-10, bad)


@pytest.mark.parametrize("entry, match", [
    (3, r"free parameter entry 3 must be a parameter path \(a string\) or a dict"),
    (("volume", "log"), r"free parameter entry \('volume', 'log'\) must be a parameter path"),
    ({"path": "volume", "bounds": (1e-6, 5e-5, 1e-4)}, r"'volume': bounds must be \(lo, hi\), two numbers"),
    ({"path": "volume", "bounds": 1e-4}, r"'volume': bounds must be \(lo, hi\), two numbers"),
    ({"path": "volume", "bounds": "ab"}, r"'volume': bounds must be \(lo, hi\), two numbers"),
    ({"path": "volume", "bounds": (0.0, float("inf"))}, r"'volume': bounds must be finite"),
])
def test_malformed_free_entries_are_refused_by_name(entry, match):
    # bounds=(lo, mid, hi) raised "too many values to unpack", an entry 3 "'int' object is not iterable"
    with pytest.raises(PamjaxInputError, match=match):
        pamjax.ParameterSpace(presets.mas10_tank_system(valve="averaged"), [entry])


def test_numpy_integer_counts_of_the_solver_and_the_loop_experiment_are_taken():
    # `LevenbergMarquardt(stall_steps=np.int64(8))` and a hysteresis loop's `substeps=np.int64(4)` were refused as
    # "must be a positive int" (a NumPy integer, as a config or an array read gives it); a bool stays refused
    pj = pamjax
    solver = pj.LevenbergMarquardt(stall_steps=np.int64(8))
    assert solver.stall_steps == 8 and type(solver.stall_steps) is int
    with pytest.raises(PamjaxInputError, match="stall_steps must be a positive int, got True"):
        pj.LevenbergMarquardt(stall_steps=True)
    x = np.linspace(0.0, 0.02, 5)
    loop = pj.bench.HysteresisLoopExperiment(x, np.full(5, 4e5), np.full(5, 0.01), np.ones(5), scale=1.0,
                                              substeps=np.int64(4))
    assert loop.substeps == 4 and type(loop.substeps) is int
    with pytest.raises(PamjaxInputError, match="substeps must be an integer >= 1"):
        pj.bench.HysteresisLoopExperiment(x, np.full(5, 4e5), np.full(5, 0.01), np.ones(5), scale=1.0, substeps=0)


def test_noise_scales_in_another_unit_are_refused_by_name():
    # scales=dict(position=0.1) meant 0.1 mm: 5x the whole recorded stroke, the position weighted 1,000x too little,
    # fitted silently; a pressure noise of 0.02 meant 0.02 bar weighted the pressure 1e5x too much.
    model = presets.mas10_system("averaged")
    signal = pamjax.Triangle(0.05, 0.95, 0.25)
    rec = pamjax.synthetic_recording(model, signal, np.linspace(0.0, 4.0, 201),
                                     noise=dict(pressure=2e3, position=1e-4), seed=0)
    with pytest.raises(PamjaxInputError, match=r"scales\['position'\] = 0.1 exceeds the whole range .*0.1 mm = 1e-4"):
        pamjax.Experiment(rec, signal, channels=["pressure", "position"], scales=dict(pressure=2e3, position=0.1))
    with pytest.raises(PamjaxInputError, match=r"scales\['pressure'\] = 0.02 Pa is below 1 Pa.*kPa or bar"):
        pamjax.Experiment(rec, signal, channels=["pressure", "position"], scales=dict(pressure=0.02, position=1e-4))
    pamjax.Experiment(rec, signal, channels=["pressure", "position"], scales=dict(pressure=2e3, position=1e-4))
