"""design: the objective's gradient (forward mode over the envelope, reverse mode per period) against central finite
differences and each other; a design raises the information over its start and keeps its constraints; the CSV
replays as the same signal; `pamjax design CONFIG.toml` writes it; bad input is named before any solve.

The system is paper 000's valve feeding the 5e-5 m³ test tank (pressure only, a few PWM periods): small programs.
"""

import math
import pathlib
import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax as pj
from pamjax import PamjaxInputError, presets
from pamjax._cli.main import main
from pamjax._core.arrays import device_array
from pamjax._fit import design_objective as obj

FREE = ["valve.inflate.discharge_coefficient", "valve.inflate.critical_ratio", "valve.exhaust.discharge_coefficient"]
NOISE = {"pressure": 2e3}
TANK = dict(channels=("pressure",), start={"pressure": 101325.0}, rate=500.0, design_rate=250.0, knots=4,
            max_duty_step=0.3, initial=pj.Constant(0.6))  # from 0.6: the tank passes the inflow's critical ratio


def _tank():
    return presets.mas10_tank_system(valve="pwm")


@eqx.filter_jit
def _at(signal, t):
    """`signal` at times `t`, one compiled program (eagerly, each of its operations would compile on its own)."""
    return signal(t)


_clip01 = jax.jit(obj.clip01)  # one program per shape (eagerly, each of its operations compiles its own)


def test_bspline_basis_is_a_partition_of_unity_and_soft_clip_inverts():
    t = np.linspace(0.0, 3.0, 301)
    b = obj.bspline_basis(t, 0.0, 3.0, 7)
    assert b.shape == (301, 7) and np.all(b >= 0)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, atol=1e-12)
    assert b[0, 0] == pytest.approx(1.0) and b[-1, -1] == pytest.approx(1.0)  # clamped ends
    z = np.linspace(-0.5, 1.5, 41)
    d = np.asarray(_clip01(z))
    assert np.all((d > 0) & (d < 1)) and np.all(np.diff(d) > 0)
    # within width·log 2 of the sharp clip, as smooth_relu promises
    assert np.max(np.abs(d - np.clip(z, 0, 1))) <= obj.CLIP_WIDTH * math.log(2) + 1e-12
    inner = d[(z > 0.05) & (z < 0.95)]
    np.testing.assert_allclose(np.asarray(_clip01(obj.unclip01(inner))), inner, atol=1e-12)


def _problem(parametrisation):
    """The compiled objective's problem for the 0.4 s tank run (20 PWM periods) as `design` builds it: no pressure
    limit and no variance floor are infinite ones, as in `design`, so that this problem, the CLI test's and every
    design of this module on the tank share one compilation of the objective and of its gradient."""
    from pamjax._fit.design import _start_coefficients, _template

    model = pj.ParameterSpace(_tank(), FREE).base
    space = pj.ParameterSpace(model, FREE)
    times = np.arange(20) * 0.02
    carrier = obj.multilevel_carrier(20, 10, 0)
    c0, basis = _start_coefficients(parametrisation, times, 0.4, 4, carrier, (0.1, 0.9), None)
    exp = _template(model, 0.4, 0.02, 250.0, ("pressure",), NOISE, {"pressure": 101325.0}, 4, np.full(20, 0.5))
    # the arrays made from NumPy with `device_array` (jnp.asarray compiles a program per shape; the scalars stay
    # jnp.asarray's weakly typed ones, as `design` makes them)
    prob = obj.DesignProblem(space=space, theta=space.initial_theta(), experiment=exp,
                             basis=None if basis is None else device_array(basis), prior=device_array(np.zeros((3, 3))),
                             weight=jnp.asarray(2.0), band=device_array([0.1, 0.9]), stroke=None,
                             max_pressure=jnp.asarray(np.inf), max_step=jnp.asarray(0.3),
                             floor=device_array(np.full(3, np.inf)), subset=(0, 1, 2), criterion="D")
    c = device_array(np.asarray(c0) + 0.5)  # level lifted off the band's bottom: every parameter is fixed there
    return c, prob


def test_forward_gradient_matches_central_differences():
    # The objective is piecewise smooth in the duty (edges move continuously inside a period); away from the band
    # ends and the 10 %/90 % dead bands a central difference of step 1e-5 agrees to its truncation error.
    c, prob = _problem("envelope")
    g = np.asarray(obj.forward_gradient(c, prob))
    h, host = 1e-5, np.asarray(c)
    for k in range(c.size):
        e = np.zeros(c.size)
        e[k] = h  # the steps on the host: eager JAX would compile each small operation on its own
        up, down = (float(obj.value(jnp.asarray(host + sign * e), prob)[0]) for sign in (1.0, -1.0))
        fd = (up - down) / (2 * h)
        assert g[k] == pytest.approx(fd, rel=1e-4, abs=1e-6 * np.max(np.abs(g)))


def test_reverse_gradient_per_period_equals_forward_mode():
    c, prob = _problem("periods")
    rev = np.asarray(obj.reverse_gradient(c, prob))
    fwd = np.asarray(obj.forward_gradient(c, prob))
    assert np.any(rev != 0)
    np.testing.assert_allclose(rev, fwd, rtol=1e-8, atol=1e-10 * np.max(np.abs(fwd)))


def test_design_raises_the_information_keeps_its_constraints_and_replays_from_csv(tmp_path):
    # Baseline: a constant-duty run of the same length; the design must match it on every parameter.
    base_rec = pj.synthetic_recording(_tank(), pj.Constant(0.3), np.arange(0.0, 0.4, 2e-3), name="base")
    base = pj.Experiment(base_rec, pj.Constant(0.3), channels=["pressure"], scales=NOISE,
                         initial={"pressure": 101325.0})
    res = pj.design(_tank(), FREE, 0.4, noise=NOISE, steps=6, baseline=[base], progress=False, **TANK)
    assert res.objective[1] < res.objective[0]  # D criterion: log det F⁻¹ went down
    assert len(res.duty) == 20 and all(0.1 <= d <= 0.9 for d in res.duty)
    assert res.constraints["feasible"] and res.constraints["largest_duty_step"] <= 0.3 + 1e-9
    ratio = np.asarray(res.standard_errors["baseline"]) / np.asarray(res.standard_errors["design"])
    assert np.all(ratio > 0.97), ratio  # the floor's penalty leaves a slack of ~1 %
    assert all(math.isinf(s) for s in res.standard_errors["prior"])  # no prior experiments: nothing known
    # the start (steps=0) is the constant 0.6 of TANK: the design beats it
    start = pj.design(_tank(), FREE, 0.4, noise=NOISE, steps=0, baseline=[base], progress=False, **TANK)
    assert start.objective[1] == pytest.approx(res.objective[0], rel=1e-9)
    path = res.to_csv(tmp_path / "design.csv")
    rec = pj.Recording.load(path)
    np.testing.assert_array_equal(rec["duty"], res.duty)
    replay = pj.Sampled(rec.t, rec["duty"], period=0.02)
    t = np.arange(0.0, 0.4, 0.005)
    np.testing.assert_array_equal(np.asarray(_at(replay, t)), np.asarray(_at(res.signal(), t)))
    with pytest.raises(FileExistsError):
        res.to_csv(path)


VALVE = [*FREE, "valve.exhaust.critical_ratio"]
TANK_BUILD = dict(channels=("pressure",), start={"pressure": 101325.0}, rate=500.0, knots=4,
                  initial=pj.Constant(0.6), build=pj.TankFromModel(5e-5))


def _tank_test(model, duty, pressure, duration=0.2):
    """A constant-duty test of `model`'s valve on the 5e-5 m³ tank from `pressure` (paper 000's E1/E2), at 500 Hz."""
    build = pj.TankFromModel(5e-5)
    t = np.arange(0.0, duration + 1e-6, 2e-3)
    name = f"u{duty}_p{pressure:.0f}"
    rec = pj.synthetic_recording(build(model), pj.Constant(duty), t, channels=["pressure"], name=name,
                                 y0=build(model).initial_state(pressure=pressure))
    return pj.Experiment(rec, pj.Constant(duty), channels=["pressure"], scales=NOISE, build=build,
                         initial={"pressure": pressure}, name=name)


@pytest.fixture(scope="module")
def tank_design():
    """A 0.4 s tank test designed for the muscle model's valve (`build=TankFromModel`), against the bench's kind
    of tank tests in the same time: a charge from atmospheric and a discharge from supply at duty 0.5, 0.2 s each."""
    model = presets.mas10_system(valve="pwm")
    base = [_tank_test(model, 0.5, 101325.0), _tank_test(model, 0.5, float(model.valve.supply_pressure))]
    res = pj.design(model, VALVE, 0.4, noise=NOISE, steps=6, baseline=base, progress=False, **TANK_BUILD)
    return model, res


def test_a_designed_tank_test_beats_constant_duty_tank_tests_of_the_same_time(tank_design):
    # `build` drives the valve's tank, not the muscle: no stroke limit, the muscle's parameters untouched; the
    # designed 0.4 s determines both flow scales at least as well as the constant-duty pair (predicted, 1 kHz-fit
    # resolution) and the D criterion went down.
    model, res = tank_design
    assert res.constraints["stroke_limits"] is None and res.constraints["position_range"] is None
    assert res.constraints["feasible"] and res.objective[1] < res.objective[0]
    design, base = (np.asarray(res.standard_errors[k]) for k in ("design", "baseline"))
    for label in ("valve.inflate.discharge_coefficient", "valve.exhaust.discharge_coefficient"):
        i = res.labels.index(label)
        assert design[i] <= base[i], (label, design[i], base[i])
    assert np.all(base / design > 0.97), base / design  # the floor's penalty: none worse (≈1 % slack)


def test_a_designed_tank_tests_information_matches_the_fits_standard_errors(tank_design):
    # The design's predicted (Cramér-Rao) errors are the fit's linearised ones on a recording of the designed signal:
    # σ² (JᵀJ)⁻¹ at the fit, σ² the fit's residual variance (divided out here). The recording is the fit's own
    # prediction plus noise of 1/100 of the bench's, so that the fit lands where the design's linearisation holds (at
    # the bench's 2 kPa, 0.4 s leave b23 loose by tens of % and the Jacobian at the fit differs by up to 20 %).
    model, res = tank_design
    t = np.arange(0.0, 0.4 + 1e-6, 2e-3)

    def experiment(pressure):
        # named as design's own verification experiment of the same run: the name is a static field of the compiled
        # residuals, so the fit's Jacobian can be the one compiled there
        rec = pj.Recording(t, {"pressure": pressure}, name="design")
        return pj.Experiment(rec, res.signal(), channels=["pressure"], scales=NOISE, build=pj.TankFromModel(5e-5),
                             initial={"pressure": 101325.0})

    clean = pj.predictions(model, [experiment(np.full(t.shape, 101325.0))])[0]["pressure"]
    noisy = clean + NOISE["pressure"] / 100 * np.random.default_rng(3).standard_normal(t.shape)
    fit = pj.fit(model, [experiment(noisy)], VALVE, max_steps=20, progress=False)
    sigma = math.sqrt(2.0 * fit.cost / (t.size - len(VALVE)))
    assert fit.status == "converged" and sigma == pytest.approx(0.01, rel=0.2)
    np.testing.assert_allclose(np.asarray(fit.standard_errors) / sigma, res.standard_errors["design"], rtol=0.02)


def test_a_start_that_leaves_a_parameter_free_is_named():
    with pytest.raises(PamjaxInputError, match=r"does not determine \['valve.inflate.critical_ratio'\]"):
        pj.design(_tank(), FREE, 0.4, noise=NOISE, steps=1, progress=False,
                  **{**TANK, "initial": pj.Constant(0.12)})


@pytest.mark.parametrize("kwargs, match", [
    (dict(noise={"position": 1e-4}), r"noise must give the noise standard deviation of every channel"),
    (dict(noise=NOISE, duty_band=(0.9, 0.1)), r"duty_band must be \(lo, hi\)"),
    (dict(noise=NOISE, subset=["k0"]), r"subset \['k0'\] must name free parameters"),
    (dict(noise=NOISE, criterion="E"), r"criterion must be 'D' or 'A'"),
    (dict(noise=NOISE, parametrisation="fourier"), r"parametrisation must be 'envelope' or 'periods'"),
    (dict(noise=NOISE, build="tank"), r"build must be a callable model → system"),
    (dict(noise=NOISE, build=lambda m: m.valve), r"build\(model\) must give a pamjax system"),
    (dict(noise=NOISE, build=lambda m: 1 / 0), r"build\(model\) failed: ZeroDivisionError"),
    (dict(noise={**NOISE, "position": 1e-4}, build=pj.TankFromModel(5e-5), channels=("pressure", "position")),
     r"channels \['position'\]: the designed system \(TankSystem, from build\) has no such output"),
    (dict(noise=NOISE, start={"position": 0.0}), r"start: bad keys \['position'\]"),
    (dict(noise=NOISE, start=101325.0), r"start must be a dict of keyword arguments"),
])
def test_bad_input_is_named_before_any_solve(kwargs, match, monkeypatch):
    monkeypatch.setattr(obj, "value", lambda *a: pytest.fail("solved before rejecting the input"))
    with pytest.raises(PamjaxInputError, match=match):
        pj.design(_tank(), FREE, 0.4, **{**TANK, **kwargs})


def test_design_needs_a_pwm_period():
    with pytest.raises(PamjaxInputError, match="period: the model's valve has no pwm_frequency"):
        pj.design(presets.mas10_tank_system(valve="averaged"), ["valve.coefficients[1,0]"], 0.4, noise=NOISE,
                  channels=("pressure",))


def test_cli_design_writes_csv_json_figure_and_refuses_to_overwrite(tmp_path, capsys):
    cfg = tmp_path / "design.toml"
    cfg.write_text(textwrap.dedent(f"""
        [model]
        preset = "mas10_tank_system"
        options = {{ valve = "pwm" }}
        [design]
        free = {FREE!r}
        duration = 0.4
        noise = {{ pressure = 2e3 }}
        channels = ["pressure"]
        start = {{ pressure = 101325.0 }}
        rate = 500.0
        knots = 4
        max_duty_step = 0.3
        initial = 0.6
        steps = 2
    """).replace("'", '"'))
    out = tmp_path / "out"
    assert main(["design", str(cfg), "--out", str(out), "--quiet"]) == 0
    rec = pj.Recording.load(out / "design.csv")
    assert rec.t.size == 20 and "duty" in rec.channels
    assert (out / "design.png").stat().st_size > 10_000
    capsys.readouterr()
    assert main(["design", str(cfg), "--out", str(out), "--quiet"]) == 2  # a user error: one line, status 2
    assert "design.csv exists; pass --overwrite" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text(cfg.read_text().replace("knots = 4", "knot = 4"))
    assert main(["design", str(bad), "--out", str(tmp_path / "o2"), "--quiet"]) == 2
    assert "[design]: unknown key(s) ['knot']" in capsys.readouterr().err
    assert not (tmp_path / "o2").exists()  # refused before the output folder was made


def test_design_example_config_loads():
    # every key of examples/design_example.toml is checked and its model built (nothing solved)
    from pamjax._cli.design import load

    model, free, duration, kwargs, out = load(pathlib.Path(__file__).resolve().parents[1] / "examples"
                                              / "design_example.toml")
    assert duration == 10.0 and len(free) == 5 and out == "results/design_example"
    assert kwargs["duty_band"] == (0.1, 0.9) and kwargs["criterion"] == "D"
    assert "build" not in kwargs


def test_design_config_tank_volume_designs_a_tank_test(tmp_path):
    # `tank_volume` in [design]: the signal drives a constant-volume tank test of the model's valve (build=), as a fit
    # experiment's tank_volume; a bad volume is refused naming the key, before anything is built or solved.
    from pamjax._cli.design import load

    body = ('[model]\npreset = "mas10_system"\noptions = { valve = "pwm" }\n[design]\n'
            'free = ["valve.inflate.discharge_coefficient"]\nduration = 2.0\nnoise = { pressure = 2e3 }\n'
            'channels = ["pressure"]\nstart = { pressure = 101325.0 }\ntank_volume = %s\n')
    cfg = tmp_path / "tank.toml"
    cfg.write_text(body % "5e-5")
    model, _, _, kwargs, _ = load(cfg)
    system = kwargs["build"](model)
    assert isinstance(system, pj.TankSystem) and float(system.volume) == pytest.approx(5e-5)
    assert system.valve is model.valve
    for bad in ("-5e-5", '"big"'):
        cfg.write_text(body % bad)
        with pytest.raises(PamjaxInputError, match=r"\[design\] tank_volume"):
            load(cfg)


def test_pressure_limit_is_penalised_and_kept():
    # The penalty: zero below the limit; above it, PENALTY·dt·Σ(excess/1 kPa)² and the worst excess reported.
    c, prob = _problem("envelope")
    free_value, free_aux = obj.value(c, prob)
    top = float(np.max(np.asarray(free_aux["pressure"])))
    for limit in (top + 1e3, top - 5e3):
        limited = eqx.tree_at(lambda p: p.max_pressure, prob, jnp.asarray(limit))
        value, aux = obj.value(c, limited)
        excess = np.maximum(np.asarray(aux["pressure"]) - limit, 0.0)
        assert float(aux["worst_pressure"]) == pytest.approx(float(np.max(excess)), abs=1e-9)
        times = np.asarray(limited.experiment.times)
        dt = float(times[1] - times[0])
        expected = obj.PENALTY * dt * np.sum((excess / obj.PRESSURE_UNIT) ** 2)
        assert float(value) - float(free_value) == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert (expected > 0) == (limit < top)
    # A design that starts within the limit stays within it (pressure predicted at the design samples).
    start = pj.design(_tank(), FREE, 0.4, noise=NOISE, steps=0, progress=False, **TANK)
    limit = start.constraints["pressure_range"][1] + 2e3
    res = pj.design(_tank(), FREE, 0.4, noise=NOISE, steps=4, progress=False, max_pressure=limit, **TANK)
    assert res.constraints["feasible"] and res.constraints["pressure_range"][1] <= limit
    assert res.objective[1] < res.objective[0]


def test_stroke_limits_are_the_stops_less_the_margin_or_the_rest_position():
    from pamjax._fit.design import stroke_limits

    muscle = presets.mas10_system(valve="pwm")
    rest = float(muscle.initial_state().position)  # the payload's equilibrium at atmospheric pressure
    lo, hi = float(muscle.muscle.min_position), float(muscle.muscle.max_position)
    assert stroke_limits(muscle, None, 0.005) == pytest.approx((lo + 0.005, hi - 0.005))
    margin = rest - lo + 0.002  # the payload rests 2 mm inside the margin: the design may go as far as the rest
    assert stroke_limits(muscle, None, margin) == pytest.approx((rest, hi - margin))
    assert stroke_limits(_tank(), None, 0.005) is None
