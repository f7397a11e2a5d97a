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
    from pamjax._fit.fit_checks import validate_fit as _validate

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
    from pamjax._fit.fit_checks import check_settings as _check_settings

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
    ({"path": "valve.coefficients", "transform": "nodes"},  # "needs an enclosing component with a None range"
     r"'valve.coefficients': a 'nodes' transform needs a polynomial whose field names the range it spans"),
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


# Misuse found by the fit API's second tester (issue: fitapi), refused by name before any solve.

def test_a_parameter_the_data_barely_see_is_flagged_and_the_covariance_is_column_normalised():
    # muscle.slack_width on a triangle run: a Jacobian column of 2.4e-10 beside ~300. The covariance cut it by the
    # unnormalised singular values (standard error 9e-19), identifiability (normalised columns) flagged nothing.
    from pamjax._fit.diagnostics import covariance, identifiability

    rng = np.random.default_rng(0)
    jac = rng.standard_normal((200, 3)) * np.array([25.0, 20.0, 2e-11])
    assert identifiability(jac, ["a", "b", "c"], 1e-6) == [["c"]]
    cost, used = 90.0, 200
    sigma2 = 2 * cost / (used - 3)
    cov = covariance(jac, cost, used, 1e-6)
    np.testing.assert_allclose(cov[:2, :2], sigma2 * np.linalg.inv(jac[:, :2].T @ jac[:, :2]), rtol=1e-10)
    assert np.all(cov[2] == 0) and np.all(cov[:, 2] == 0)  # left out, as identifiability says
    # well conditioned, nothing left out: σ²(JᵀJ)⁻¹ to rounding, whatever the columns' scales
    jac = rng.standard_normal((200, 3)) * np.array([3e3, 1.0, 2e-2])
    assert identifiability(jac, ["a", "b", "c"], 1e-6) == []
    np.testing.assert_allclose(covariance(jac, cost, used, 1e-6), sigma2 * np.linalg.inv(jac.T @ jac), rtol=1e-10)


@pytest.mark.parametrize("values, match", [
    ([3e-5, 20.0, 2e-3, 999.0], r"values must be 3 numbers, one per label \(muscle.volume_law.v0, "
                                r"friction.coulomb_force, valve.coefficients\[1,0\]\); got shape \(4,\)"),
    ([3e-5, 20.0], r"values must be 3 numbers.*got shape \(2,\)"),
    ([[3e-5, 20.0, 2e-3]], r"values must be 3 numbers.*got shape \(1, 3\)"),
    ({"friction.coulomb_force": 20.0}, r"values must be 3 numbers.*got a dict"),
    ([3e-5, float("nan"), 2e-3], r"values: friction.coulomb_force = nan is non-finite"),
    ([-3e-5, 20.0, 2e-3], r"values: muscle.volume_law.v0 = -3e-05 is negative; .* log space"),
])
def test_with_values_refuses_a_wrong_count_shape_or_value(values, match):
    # 4 values for 3 parameters dropped the 4th silently; 2, a 2-D row or a dict raised raw NumPy errors
    space = pamjax.ParameterSpace(presets.mas10_system("averaged"),
                                  ["muscle.volume_law.v0", "friction.coulomb_force", "valve.coefficients[1,0]"])
    with pytest.raises(PamjaxInputError, match=match):
        space.with_values(values)
    space.with_values([3e-5, 20.0, 2e-3])
    bounded = pamjax.ParameterSpace(presets.mas10_system("averaged"),
                                    [{"path": "friction.coulomb_force", "bounds": (1.0, 40.0)}])
    with pytest.raises(PamjaxInputError, match=r"friction.coulomb_force = 50 lies outside its bounds \(1, 40\)"):
        bounded.with_values([50.0])
    bounded.with_values(np.asarray(bounded.physical(np.array([60.0]))))  # at the bound, rounded: taken


def test_fit_out_and_checkpoint_that_cannot_be_written_are_refused_before_the_fit(tmp_path):
    # out under a file, out a folder (overwrite=True) and a checkpoint under a file failed after the fit (or its
    # first iteration) as raw FileExistsError / IsADirectoryError, the result lost
    (tmp_path / "afile").write_text("")
    (tmp_path / "folder").mkdir()
    exp = pamjax.Experiment(_recording(), pamjax.Constant(0.5))
    steps = []
    for kwargs, match in ((dict(out=tmp_path / "afile" / "fit.json"), r"out .* lies under .*afile.*which is a file"),
                          (dict(out=tmp_path / "folder", overwrite=True), r"out .*folder' is a folder: give the path"),
                          (dict(checkpoint=tmp_path / "afile" / "ck.npz"), r"checkpoint .* lies under .*a file")):
        with pytest.raises(PamjaxInputError, match=match):
            pamjax.fit(presets.mas10_tank_system("averaged"), exp, ["volume"], progress=lambda *a: steps.append(a),
                       **kwargs)
    assert steps == []


def test_synthetic_recording_refuses_bad_noise_and_seeds():
    model = presets.mas10_system("averaged")
    signal = pamjax.Triangle(0.05, 0.95, 0.25)
    ts = np.linspace(0.0, 4.0, 201)  # the recording of test_noise_scales_in_another_unit_are_refused_by_name
    for kwargs, match in (
        (dict(noise=dict(pressure=np.nan)), r"noise\['pressure'\] must be a finite standard deviation >= 0"),
        (dict(noise=dict(velocity=1e-3)), r"noise names channel 'velocity', which is not recorded; the recorded "
                                          r"channels are \['pressure', 'position', 'command'\]"),
        (dict(seed=-1), r"seed must be an int >= 0"), (dict(seed=1.5), r"seed must be an int >= 0"),
        (dict(noise=dict(pressure=0.02)), r"noise\['pressure'\] = 0.02 Pa is below 1 Pa.*kPa or bar"),
        (dict(noise=dict(position=0.1)), r"noise\['position'\] = 0.1 exceeds the whole range .*0.1 mm = 1e-4"),
    ):
        with pytest.raises(PamjaxInputError, match=match):
            pamjax.synthetic_recording(model, signal, ts, **kwargs)
    rec = pamjax.synthetic_recording(model, signal, ts, noise=dict(pressure=2e3, velocity=1e-3), seed=np.int64(1),
                                     channels=["pressure", "velocity"])
    assert sorted(rec.channels) == ["pressure", "velocity"]


def _two_channels():
    t = np.linspace(0.0, 0.1, 5)
    return pamjax.Recording(t, {"pressure": np.full(5, 2e5), "position": np.full(5, 0.01)}, name="r")


def test_an_unknown_part_of_the_residuals_is_refused():
    # part="validaton" (or "test") was taken as "all"
    exp = pamjax.Experiment(_two_channels(), pamjax.Constant(0.5))
    for part in ("validaton", "test", None):
        with pytest.raises(PamjaxInputError, match=r"part must be one of 'identification', 'validation', 'all'"):
            exp.residuals_of({}, part)
    force_map = pamjax.bench.ForceMapExperiment(np.zeros(3), np.full(3, 3e5), np.ones(3), scale=1.0)
    with pytest.raises(PamjaxInputError, match=r"part must be one of"):
        force_map.residuals(presets.mas10_muscle(), "Validation")


def test_a_compared_channel_with_every_sample_masked_is_refused():
    # it dropped out of the fit unseen (channel_errors {'range': 1.0}, no warning)
    rec = _two_channels()
    masked = pamjax.Recording(rec.t, {"pressure": np.full(5, np.nan), "position": rec["position"]}, mask_nan=True,
                              name="m")
    with pytest.raises(PamjaxInputError, match=r"experiment 'm': channel 'pressure' has no valid sample \(all masked"):
        pamjax.Experiment(masked, pamjax.Constant(0.5), channels=["pressure", "position"])
    pamjax.Experiment(masked, pamjax.Constant(0.5), channels=["position"])


def test_an_initial_position_in_mm_or_outside_the_stroke_is_refused():
    # initial={"position": 20} (20 mm meant), 0.5 m or -0.3 m outside the stroke [-0.02, 0.075] m were never checked
    model = presets.mas10_system("averaged")
    for position, match in ((20.0, r"experiment 'r': .*initial.position = 20 m: .*looks like mm"),
                            (0.5, r"experiment 'r': initial.position = .*0.5.* m lies outside the stroke"),
                            (-0.3, r"experiment 'r': initial.position = .*-0.3.* m lies outside the stroke")):
        with pytest.raises(PamjaxInputError, match=match):
            pamjax.Experiment(_two_channels(), pamjax.Constant(0.5), initial={"position": position}).check(model)
    pamjax.Experiment(_two_channels(), pamjax.Constant(0.5), initial={"position": 0.01}).check(model)


def test_staged_start_lists_each_stages_entries_with_their_array_index(monkeypatch):
    # StagedStart.stages listed ['valve.coefficients', 'valve.coefficients'] for [1,0] and [1,1]: the index stripped
    import pamjax._fit.staged as staged_module

    class Done:  # a stage's result, without fitting: where it started, converged
        message, status = "converged", "converged"

        def apply(self, model):
            return model

    monkeypatch.setattr(staged_module, "fit", lambda *args, **kwargs: Done())
    monkeypatch.setattr(staged_module, "_balanced_start", lambda model, full, rest: (model, None))
    model = presets.mas10_system(valve="averaged", friction="karnopp")
    rec = pamjax.Recording(np.linspace(0.0, 0.1, 5), {"pressure": np.full(5, 2e5), "position": np.zeros(5)})
    run = pamjax.Experiment(rec, pamjax.Constant(0.5), name="tri")
    tank = pamjax.Experiment(_recording(), pamjax.Constant(0.5), build=pamjax.TankFromModel(5e-5), name="tank")
    free = ["valve.coefficients[1,0]", "valve.coefficients[1,1]", "friction.coulomb_force"]
    staged = pamjax.staged_start(model, [run, tank], free, max_steps=2, progress=False, background_compile=False)
    assert [(name, entries) for name, entries, *_ in staged.stages] == [
        ("1", ["valve.coefficients[1,0]", "valve.coefficients[1,1]"]), ("2", ["friction.coulomb_force"])]


# -- checkpoints and the fingerprint (tester t66d) ---------------------------------------------------------------
def test_numpy_bounds_and_scales_in_a_free_entry_are_fingerprinted_as_plain_numbers():
    # np.array([100, 400]) or (np.int64(100), np.int64(400)) bounds (float32 too) crashed every fit with a raw
    # TypeError "'numpy.int64' object is not iterable" from the fingerprint; ParameterSpace took them
    import jax.numpy as jnp
    from problems import force_map

    from pamjax._files.fingerprint import fingerprint

    muscle, exp = force_map()
    plain = fingerprint(muscle, [exp], [{"path": "force_law.k0", "bounds": [50.0, 200.0], "scale": 2.0}])["free"]
    for bounds, scale in ((np.array([50, 200]), np.int64(2)), ((np.int64(50), np.int64(200)), np.float32(2.0)),
                          ((np.float32(50), np.float32(200)), np.array(2.0)), (jnp.array([50.0, 200.0]), 2)):
        free = [{"path": "force_law.k0", "bounds": bounds, "scale": scale}]
        assert fingerprint(muscle, [exp], free)["free"] == plain
    free = ["force_law.k1", {"path": "force_law.k0", "bounds": np.array([50, 200])}]
    assert pamjax.fit(muscle, [exp], free, max_steps=1, progress=False).iterations == 1


@pytest.fixture(scope="module")
def checkpointed(tmp_path_factory):
    """A force-map fit from a start off the minimum, stopped at max_steps = 3 with its checkpoint."""
    from problems import FORCE_MAP_FREE, force_map

    muscle, exp = force_map()
    space = pamjax.ParameterSpace(muscle, FORCE_MAP_FREE)
    start = space.with_values(np.asarray(space.initial_values()) * 1.3)
    path = tmp_path_factory.mktemp("checkpoint") / "fit.npz"
    res = pamjax.fit(start, [exp], FORCE_MAP_FREE, max_steps=3, checkpoint=path, progress=False)
    assert res.status == "max_steps"
    return start, exp, FORCE_MAP_FREE, path, res


def test_a_truncated_checkpoint_is_refused_naming_resume(checkpointed, tmp_path):
    # a checkpoint cut short (a full disk, a partial copy) was a raw zipfile.BadZipFile, or EOFError at 0 bytes
    start, exp, free, path, _ = checkpointed
    raw = path.read_bytes()
    for cut, error in ((len(raw) // 2, "BadZipFile"), (0, "EOFError")):
        (tmp_path / "cut.npz").write_bytes(raw[:cut])
        with pytest.raises(PamjaxInputError, match=rf"resume: .*cut\.npz is not a readable pamjax fit checkpoint "
                                                   rf"\({error}: .*start again without resume"):
            pamjax.fit(start, [exp], free, max_steps=20, resume=tmp_path / "cut.npz", progress=False)


def test_a_resume_with_fewer_max_steps_than_the_checkpoint_holds_is_refused(checkpointed):
    # it returned the checkpoint's iterations (3 of max_steps = 2, status 'max_steps'), where an uninterrupted fit
    # with max_steps = 2 ends elsewhere
    start, exp, free, path, res = checkpointed
    with pytest.raises(PamjaxInputError, match=rf"max_steps = 2: the checkpoint resumed already holds "
                                               rf"{res.iterations} iterations.*resume with max_steps >= "
                                               rf"{res.iterations}"):
        pamjax.fit(start, [exp], free, max_steps=2, resume=path, progress=False)
    same = pamjax.fit(start, [exp], free, max_steps=res.iterations, resume=path, progress=False)
    assert same.values == res.values and same.iterations == res.iterations  # as many as it holds: its end


def test_a_start_whose_solve_runs_out_of_steps_names_the_experiment_and_its_max_steps():
    # An 800 s run failed its solve at the experiment's max_steps and the fit blamed "the start values and the
    # experiments' initial states": the message names the experiment whose solve failed (not the one that solved),
    # why (its max_steps) and the budget that finishes it
    system = presets.mas10_system(valve="averaged")
    rec = pamjax.Recording(np.linspace(0, 0.5, 11), dict(pressure=np.full(11, 2e5)), name="r")
    exps = [pamjax.Experiment(rec, pamjax.Constant(0.5), stepping="adaptive", name=name, max_steps=steps)
            for name, steps in (("ok", 100_000), ("long", 2))]
    with pytest.raises(PamjaxInputError, match=r"experiment 'long': its solve fails: the maximum number of solver "
                                               r"steps was reached: max_steps=2 .*raise its max_steps \(e\.g\. "
                                               r"max_steps = \d+\)") as caught:
        pamjax.fit(system, exps, ["payload_mass"], progress=False)
    assert "'ok'" not in str(caught.value) and "check the start values" not in str(caught.value)


@pytest.mark.parametrize("start, free, match", [
    (dict(exponent=1.0), ["exponent", "transition_length"],
     r"exponent = 1 is on the bound of its range \(1, 10\).*e\.g\. 1\.09, or keep it fixed"),
    (dict(shape=1.0), ["shape"], r"shape = 1 is on the bound of its range \(0, 1\).*e\.g\. 0\.99"),
])
def test_a_fit_started_on_a_bound_of_a_logistic_names_only_that_parameter(start, free, match, recwarn):
    # Dahl's limits of the Bouc-Wen law (n = 1, beta = 1, documented) freed there: NumPy's divide-by-zero warnings,
    # then "non-finite transformed parameters: {'exponent': -inf, 'transition_length': 0.0}", the finite one listed
    # as if at fault and no word of the bound
    friction = pamjax.BoucWenFriction(**start)
    exp = pamjax.bench.FrictionCurveExperiment([-0.01, 0.01, 0.02], [-20.0, 20.0, 21.0], friction="")
    with pytest.raises(PamjaxInputError, match=match) as refused:
        pamjax.fit(friction, [exp], free, max_steps=1)
    assert "transition_length" not in str(refused.value)  # only the parameter at fault
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


def test_parameter_paths_of_no_model_and_a_table_of_unknown_truth_are_named():
    # parameter_paths(3.0) and (None) gave {} without a word; table(truth=...) printed NaN for a misspelt label
    for bad in (3.0, None):
        with pytest.raises(pamjax.PamjaxInputError, match=r"parameter_paths: model must be a pamjax model"):
            pamjax.parameter_paths(bad)
    result = pamjax.FitResult(labels=["v1"], paths=["v1"], values=[1.0], initial_values=[1.0], standard_errors=[0.1],
                          correlation=np.eye(1), cost=0.0, initial_cost=0.0, iterations=1, accepted_steps=1,
                          status="converged", converged=True, message="", channel_errors={}, mismatch=False,
                          non_identifiable=[], warnings=[], history=[], fit_s=0.0, compile_s=0.0, num_residuals=1)
    assert "v1" in result.table(truth={"v1": 1.0})
    with pytest.raises(pamjax.PamjaxInputError, match=r"truth has label\(s\) \['v_1'\] that the fit does not have"):
        result.table(truth={"v_1": 1.0})


# evaluate / predictions: their `experiments` checked as fit checks them, and a failed solve named (issue t69a).

@pytest.mark.parametrize("call, match", [
    (lambda m, e, r: pamjax.evaluate(m, []), r"experiments must be a non-empty list"),
    (lambda m, e, r: pamjax.predictions(m, []), r"experiments must be a non-empty list"),  # returned []
    (lambda m, e, r: pamjax.evaluate(m, {"run": e}), r"got a dict: pass list\(experiments\.values\(\)\)"),
    (lambda m, e, r: pamjax.evaluate(e, m), r"model must be .*got the Experiment 'r': the arguments are \(model, "),
    (lambda m, e, r: pamjax.evaluate(m, [r]), r"must be pamjax experiments .*got Recording: .*pj\.Experiment\("),
    (lambda m, e, r: pamjax.predictions(m, iter([e])), r"got list_iterator: pass a list"),
    (lambda m, e, r: pamjax.predictions(m, [e, e]), r"experiment names must be unique"),
])
def test_evaluate_and_predictions_check_their_experiments_as_fit_does(call, match):
    # raw ValueError ("need at least one array to concatenate") and AttributeErrors; predictions(model, []) gave []
    model = presets.mas10_tank_system(valve="averaged")
    rec = _recording()
    with pytest.raises(PamjaxInputError, match=match):
        call(model, pamjax.Experiment(rec, pamjax.Constant(0.5)), rec)


def test_evaluate_and_predictions_name_an_experiment_whose_solve_fails():
    # max_steps=5: the predictions were NaN with no word, evaluate's rmse NaN and its autocorrelations 0.0 ("white")
    model = presets.mas10_tank_system(valve="averaged")
    exp = pamjax.Experiment(_recording(), pamjax.Constant(0.5), max_steps=5)
    for call in (pamjax.evaluate, pamjax.predictions):
        with pytest.raises(pamjax.PamjaxSolveError, match=r"experiment 'r': its solve fails: .*max_steps=5 .*raise "
                                                          r"its max_steps \(e\.g\. Experiment\(\.\.\., max_steps="):
            call(model, [exp])
