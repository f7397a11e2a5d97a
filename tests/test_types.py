"""The jaxtyping annotations of pamjax's public signatures (docs/architecture.md, "Types"), checked.

1. Every public function and class constructor of `pamjax`, `pamjax.bench`, `pamjax.runtime`, `pamjax.unchecked`
   and `pamjax.presets` annotates every argument (functions their return too).
2. Checked with beartype through jaxtyping's import hook, in a subprocess (the hook must be installed before pamjax
   is imported, and this process imported it already): each case below calls a public entry point either with
   valid input, which must pass (Python floats and lists where arrays are accepted, NumPy arrays, tracers under
   `jit`/`vmap`; the fields of what it builds must match their annotations too), or with one wrongly typed
   argument, which must raise a type error naming that argument. One subprocess runs every case (~15 s; the fit's
   cases fit a 0.2 s tank test's volume in a few steps).
3. Without the hook nothing is checked and nothing is wrapped: `import pamjax` does not import beartype, and the
   public functions are pamjax's own (no typechecking wrapper on any run).

`python tests/test_types.py` runs the cases with the hook (the worker) and prints one JSON line per case.
"""

import dataclasses
import inspect
import json
import os
import pathlib
import subprocess
import sys
import typing

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
# The layers whose modules are type-checked by the hook: every one the public namespaces re-export from; not the
# command line (`pamjax._cli`, not a Python API) nor the gallery's scripts.
CHECKED = ["pamjax._core", "pamjax._physics", "pamjax._systems", "pamjax._solve", "pamjax._sweep", "pamjax._control",
           "pamjax._bands", "pamjax._fit", "pamjax._files", "pamjax._bench", "pamjax._identifiability",
           "pamjax.presets"]
NAMESPACES = ("pamjax", "pamjax.bench", "pamjax.runtime", "pamjax.unchecked", "pamjax.presets")


def _public_callables():
    """(qualified name, object) of every public function and class the namespaces export, once each."""
    import importlib
    import warnings

    seen, out = set(), []
    for namespace in NAMESPACES:
        module = importlib.import_module(namespace)
        for name in sorted(dir(module)):
            if name.startswith("_"):
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DeprecationWarning)
                obj = getattr(module, name)
            if not (inspect.isfunction(obj) or inspect.isclass(obj)) or id(obj) in seen:
                continue
            home = getattr(obj, "__module__", "") or ""
            if not home.startswith("pamjax") or (inspect.isclass(obj) and issubclass(obj, BaseException)):
                continue
            seen.add(id(obj))
            out.append((f"{namespace}.{name}", obj))
    return out


def test_every_public_signature_is_annotated():
    public = _public_callables()
    assert len(public) > 150, f"only {len(public)} public names found"
    missing = []
    for name, obj in public:
        signature = inspect.signature(obj)
        for p in signature.parameters.values():
            bare_any = p.annotation is typing.Any and p.kind is not p.VAR_KEYWORD
            if p.annotation is inspect.Parameter.empty or bare_any:
                missing.append(f"{name}: argument {p.name!r}")
        if inspect.isfunction(obj) and signature.return_annotation is inspect.Signature.empty:
            missing.append(f"{name}: return")
    assert not missing, "public signatures without a type annotation:\n" + "\n".join(missing)


def test_import_loads_no_typechecker_and_wraps_nothing():
    # beartype is a test dependency only; the import hook exists only in the worker; on an ordinary run every public
    # function is pamjax's own code object (no jaxtyping or beartype wrapper between the user and the function)
    home = str(ROOT / "pamjax")
    code = f"""if True:
        import sys, inspect, pamjax, pamjax.bench, pamjax.runtime, pamjax.unchecked, pamjax.presets
        assert "beartype" not in sys.modules, "import pamjax imported beartype"
        for ns in (pamjax, pamjax.bench, pamjax.runtime, pamjax.unchecked, pamjax.presets):
            for name in dir(ns):
                f = getattr(ns, name)
                if inspect.isfunction(f) and f.__module__.startswith("pamjax"):
                    assert not hasattr(f, "__wrapped__"), name
                    assert f.__code__.co_filename.startswith({home!r}), (name, f.__code__.co_filename)
    """
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_env(), capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr


# --- the cases: valid calls (expected None) and wrongly typed ones (expected: the argument's name) -----------------
CASES = {}


def case(name, wrong=None):
    """Register a case; `wrong`: the argument whose type is wrong (the type error must name it), None: valid."""

    def register(fn):
        CASES[name] = (fn, wrong)
        return fn

    return register


def _pj():
    import pamjax
    import pamjax.presets
    import pamjax.runtime
    import pamjax.unchecked

    return pamjax


@case("components from presets, every valve and friction")
def _presets():
    pj = _pj()
    p = pj.presets
    return [p.mas10_system(valve, friction) for valve in ("pwm", "exact", "averaged")
            for friction in ("coulomb", "karnopp", "bristle", "bouc_wen")] + [
        p.mas10_system("averaged", payload_mass=12), p.mas10_tank_system(valve="averaged", volume=4e-5),
        p.mas10_valve(silencer=True), p.mas10_silencer(), p.dmsp40_muscle(), p.paper001_restriction(),
        p.mas10_averaged_valve(), pj.vppm_regulator("fast", hysteresis=False), pj.vppm_regulator(supply_pressure=8e5)]


@case("components built by hand: numbers, NumPy values, lists and tuples")
def _components():
    pj = _pj()
    inflate = pj.EllipseRestriction(0.36, 0.28, 3.14e-6)
    exhaust = pj.SeriesRestriction(pj.ISO6358Restriction(np.float64(7e-9), 0.4), pj.PorousRestriction(2e-14))
    valve = pj.OnOffValve(inflate, exhaust, supply_pressure=6.5e5, pwm_frequency=50, mode="exact")
    force = pj.PolynomialForce([600.0, 1e3, 0.0, 0.0, 0.0], 100.0, 1400, 3e4)
    muscle = pj.Muscle(force, pj.LinearVolume(2.6e-5, 1.9e-4), min_position=-0.02, max_position=0.075)
    braid = pj.Muscle(pj.ChouHannafordForce(0.39, 7.9, 0.3), pj.BraidVolume.from_datasheet(0.3, 0.01, 0.25), 0.0, 0.07)
    tondu = pj.TonduLopezForce(0.005, 0.4, 0.3, correction=1)
    return [
        pj.Air(temperature=300), pj.NozzleRestriction(0.8), valve, muscle, braid, tondu,
        pj.CubicVolume((2e-4, 1e-4, 0.0, 0.0), 0.4), pj.AveragedValve.from_m(np.zeros(9)), pj.AveragedValve(np.eye(3)),
        pj.TabulatedISO6358Restriction([2e5, 4e5, 6e5], [7e-9, 7.5e-9, 8e-9], (0.3, 0.35, 0.4)),
        pj.MuscleSystem(valve, muscle, payload_mass=np.float32(9.6), friction=pj.KarnoppFriction(16, 250)),
        pj.TankSystem(valve, 5e-5), pj.EndStops(), pj.BristleFriction(), pj.BoucWenFriction(exponent=1.5),
        pj.CoulombViscousFriction(velocity_width=2e-3),
        pj.LinearRegulator(), pj.FeedbackRegulator(), pj.PressureHysteresis(),
        pj.ISO6358Regulator(pj.VoltageCalibration([0.0, 5.0, 10.0], np.array([0.0, 5e5, 1e6])), internal_volume=1e-4),
        pj.RegulatorSystem(pj.LinearRegulator(), volume=0.04), pj.RegulatedMuscleSystem(pj.ISO6358Regulator(),
                                                                                        pj.presets.dmsp40_muscle()),
        pj.MuscleState(5e5, 0.0, 0.0), pj.TankState(np.asarray(2e5)),
        pj.ISO6358RegulatorState(pilot=1e5, pilot_output=1e5, pressure=1e5),
    ]


@case("signals: numbers, lists, NumPy arrays")
def _signals():
    pj = _pj()
    return [pj.Constant(0.5), pj.Constant(np.array([1.0, 2.0])), pj.Step(0, 1.0, 0.1), pj.Triangle(),
            pj.Sine(0.5, 0.2, frequency=2), pj.Sampled([0, 1, 2], [0.1, 0.2, 0.3]),
            pj.Sampled(np.arange(3.0), np.ones(3), period=0.02), pj.SquareWave(low=0, high=3),
            pj.VoltagePair(pj.Constant(2.0), pj.Step(1.0, 3.0, 0.5))]


@case("a joint, its controller and loop")
def _joint():
    pj = _pj()
    m = pj.presets.dmsp40_muscle()
    joint = pj.AntagonisticJoint(pj.ISO6358Regulator(), pj.ISO6358Regulator(), m, m, foot_mass=0)
    loop = pj.JointControlLoop(joint, pj.AntagonisticJointController(), pj.GaitAngle(frequency=0.5),
                               pj.Step(160.0, 160.0, 0.0))
    k = pj.regulated_stiffness(joint, 0.1, 4e5, 3e5)
    return [joint, loop, loop.initial_state(), k]


@case("closed loops and controllers")
def _closed_loop():
    pj = _pj()
    plant = pj.presets.mas10_system("averaged")
    model = pj.presets.mas10_system("averaged")
    ekf = pj.ExtendedKalmanFilter(model, measurement_noise=[2e3, 1e-4])
    return [pj.ClosedLoop(plant, pj.PIController(), pj.Sine(0.03, 0.01, 0.5)),
            pj.ClosedLoop(plant, pj.PIDController(seed=3), pj.Constant(0.03), 0.02, stepping="grid"),
            pj.ClosedLoop(plant, pj.SlidingModeController(model), pj.Constant(0.03), estimator=ekf),
            pj.LoopSensors(noise=(1e3, 1e-4), seed=2), pj.KalmanState(mean=np.zeros(2), covariance=np.eye(2)),
            pj.equivalent_duty(pj.presets.mas10_averaged_valve(), 1e-4, 3e5, pj.Air())]


@case("simulate: a list of times, NumPy and JAX values")
def _simulate():
    pj = _pj()
    tank = pj.presets.mas10_tank_system(valve="averaged")
    a = pj.simulate(tank, pj.Constant(0.5), [0.0, 0.01, 0.02], stepping="grid", grid_step=0.005)
    b = pj.simulate(tank, pj.Constant(np.float64(0.5)), np.linspace(0.0, 0.02, 3), y0=pj.TankState(np.asarray(2e5)),
                    t0=0, rtol=1e-5, atol=np.float64(1e-5), stepping="grid", grid_step=0.005)
    return [a, b]


@case("under jit and vmap: tracers through the annotations")
def _traced():
    import jax
    import jax.numpy as jnp

    pj = _pj()
    tank = pj.presets.mas10_tank_system(valve="averaged")
    valve = pj.presets.mas10_valve()

    @jax.jit
    def run(ts, duty):
        traj = pj.unchecked.solve(tank, pj.Constant(duty), ts, None, ts[0], stepping="grid", num_periods=4,
                                  grid_step=0.005)
        return traj

    traj = run(jnp.linspace(0.0, 0.02, 3), 0.5)
    air = jax.vmap(lambda t: pj.Air(temperature=t))(jnp.array([290.0, 300.0]))
    flows = jax.vmap(lambda u: pj.cycle_averaged_flow(valve, u, 3e5, pj.Air(), samples=8))(jnp.linspace(0, 1, 3))
    k = jax.jit(lambda x, p: pj.muscle_stiffness(pj.presets.mas10_muscle(), x, p, pj.Air()))(0.01, 3e5)
    rate = jax.vmap(lambda x: pj.stiffness_rate(pj.presets.mas10_muscle(), x, 0.01, 3e5, 1e5))(jnp.zeros(2))
    state = jax.jit(lambda s: pj.unchecked.discrete_step(tank, 0.0, s, 0.5, 1e-4))(tank.initial_state())
    assert jnp.shape(air.temperature) == (2,) and jnp.shape(flows) == (3,) and jnp.shape(rate) == (2,)
    return [traj, k, state]


@case("discrete model, linearisation, gradient check, PWM periods")
def _solve_tools():
    pj = _pj()
    tank = pj.presets.mas10_tank_system(valve="averaged")
    disc = pj.simulate_discrete(tank, pj.Constant(0.5), 1e-3, 0.005)
    ss = pj.linearise(tank, tank.initial_state(pressure=3e5), 0.5)
    eq = pj.equilibrium(tank, 0.5, tank.initial_state(pressure=4e5))
    check = pj.gradient_check(lambda air, adjoint: air.temperature * air.gas_constant, pj.Air(),
                              relative_steps=(1e-3, 1e-4))
    n = pj.unchecked.num_periods(pj.presets.mas10_valve(), 0.0, np.float64(0.1))
    assert n == 5 and set(check) >= {"names", "error_fd"}
    return [disc, ss, eq, pj.unchecked.default_solver(tank)]


@case("sweep, flow surface and a merged shard")
def _sweep():
    pj = _pj()
    tank = pj.presets.mas10_tank_system(valve="averaged")
    ts = np.linspace(0.0, 0.01, 3)
    r = pj.sweep(tank, pj.Constant(0.5), ts, {"signal.value": [0.2, 0.8]}, method="rk4", dt=0.005,
                 reduce=pj.FinalValue(), progress=False)
    local = pj.sweep(tank, pj.Constant(0.5), ts, {"signal.value": np.array([0.2, 0.8])}, method="rk4", dt=0.005,
                     gather="local", progress=False)
    merged = pj.merge_sweep_shards([local])
    surface = pj.flow_surface(pj.presets.mas10_valve(), [0.0, 0.5, 1.0], np.array([2e5, 4e5]), pj.Air(), samples=8)
    assert surface.shape == (3, 2)
    return [r, local, merged, pj.WindowMean(1), pj.FourierCoefficient(2, frequency=1.5)]


@case("maps and a closed loop, short")
def _maps():
    pj = _pj()
    tank = pj.presets.mas10_tank_system(valve="averaged")
    steady = pj.steady_state_map(tank, [0.2, 0.8], horizon=0.02, window=0.01, method="rk4", dt=0.005, progress=False)
    response = pj.frequency_response(tank, np.array([20.0, 40.0]), periods=1, settle_periods=0, samples_per_period=8,
                                     channels=("pressure",), method="rk4", progress=False)
    loop = pj.ClosedLoop(pj.presets.mas10_system("averaged"), pj.PIController(), pj.Constant(0.03), stepping="grid",
                         substeps=4)
    closed = pj.simulate_closed_loop(loop, 0.04, samples_per_period=2)
    return [steady, response["result"], closed]


@case("a prediction band from a parameter covariance")
def _band():
    pj = _pj()
    from pamjax._bands.uncertainty import FitUncertainty

    unc = FitUncertainty(("temperature",), ("temperature",), np.array([293.0]), np.array([[4.0]]))
    band = pj.prediction_band(unc, lambda air: air.temperature * 2.0, model=pj.Air(), check_linearity=False)
    return [unc, band]


@case("runtime knobs")
def _runtime():
    pj = _pj()
    status = pj.runtime.xla_cpu_status()
    choice = pj.runtime.select_devices("batched", "cpu")
    assert set(status) >= {"active", "fast_compile"}
    return [choice, pj.runtime.CompileStats(), pj.presets.device_array([1.0, 2.0])]


_MEMO = {}


def _tank_problem():
    """A tiny fit problem, built once per worker: a 0.2 s tank charge through the averaged valve (41 samples, fixed
    RK4 grid), its volume to fit from a start 10 % off."""
    if "tank" not in _MEMO:
        pj = _pj()
        tank = pj.presets.mas10_tank_system(valve="averaged")
        rec = pj.synthetic_recording(tank, pj.Constant(0.6), np.linspace(0.0, 0.2, 41), noise={"pressure": 500.0},
                                     seed=1, stepping="grid", grid_step=0.005)
        exp = pj.Experiment(rec, pj.Constant(0.6), scales={"pressure": 500}, stepping="grid")
        _MEMO["tank"] = pj.presets.mas10_tank_system(valve="averaged", volume=4.5e-5), exp
    return _MEMO["tank"]


@case("recordings and experiments: lists, NumPy arrays, files")
def _recordings():
    import tempfile

    pj = _pj()
    listed = pj.Recording([0.0, 0.01, 0.02, 0.03], {"pressure": [1.2e5, 1.3e5, 1.4e5, 1.45e5]}, name="listed")
    t = np.arange(40) * 1e-3
    arrays = pj.Recording(t, {"pressure": np.linspace(1.2, 1.45, 40), "command": np.full(40, 0.5)},
                          units={"pressure": "bar abs"}, atmosphere=np.float64(101325), source="bench/E1.csv")
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        from_csv = pj.Recording.from_csv(arrays.to_csv(folder / "r.csv"), name="csv", unit_checks=True)
        loaded = pj.Recording.load(str(arrays.to_npz(folder / "r.npz")), rename={"command": "duty"})
    shorter = arrays.filtered(20, channels=["pressure"]).resampled(500).window(0.0, np.float64(0.03))
    assert len(from_csv) == 40 and "duty" in loaded.channels and len(shorter) == 16
    return [
        pj.Experiment(listed, pj.Constant(0.5), channels=["pressure"], scales={"pressure": 500},
                      build=pj.TankFromModel(5e-5), initial={"pressure": 1.2e5}, t0=0, name="E", rtol=1e-8,
                      atol=np.float64(1e-8), max_steps=1000, dt0=1e-4, validation_fraction=0.25, stepping="grid",
                      substeps=8, sensors="bench"),
        pj.Experiment(arrays, pj.Constant(np.float64(0.5)), channels=("pressure",), initial={"pressure": "supply"}),
        pj.TankFromModel(np.float64(5e-5), polytropic_index=1),
        pj.PayloadFromModel(np.float64(20.0)), pj.PayloadFromModel(20),
    ]


@case("static bench tests and their reductions")
def _static():
    pj = _pj()
    b = pj.bench
    x, p, v, f = [0.0, 0.01, 0.01, 0.0], np.full(4, 4e5), (0.01, 0.01, -0.01, -0.01), np.array([300.0, 250, 280, 330])
    force_map = b.ForceMapExperiment([0.0, 0.01, 0.02], np.array([3e5, 3e5, 4e5]), (100, 50, 0), scale=5,
                                     slack_force=1, name="fm")
    errors = pj.evaluate(pj.presets.mas10_system("averaged"), force_map)
    assert set(errors) == {"fm"}
    velocity, force, _ = b.constant_velocity_point([0, 0.1, 0.2], [0.0, 0.001, 0.002], np.array([10.0, 11.0, 12.0]))
    averaged = b.loop_average(x, p, v, f, decimals=6)
    karnopp = pj.KarnoppFriction(16, 250)
    flows = b.flow_curve(pj.presets.mas10_valve().inflate, 5e5, [0.2, 0.5], pj.Air())
    steady = b.steady_friction_force(karnopp, [0.01, -0.01])
    path = b.path_friction_force(karnopp, [0.0, 0.001], np.array([0.01, 0.01]), [True, False], substeps=2)
    assert np.shape(flows) == np.shape(steady) == np.shape(path) == (2,) and len(averaged) == 4
    return [force_map, b.FrictionCurveExperiment([-0.01, 0.01], [-20.0, 20.0], scale=np.float64(1.0)),
            b.FlowCurveExperiment([5e5, 5e5], np.array([2e5, 4e5]), [1e-3, 5e-4], restriction="valve.inflate"),
            b.LoopForceMapExperiment(x, p, v, f, slack_force=0), b.HysteresisLoopExperiment(
                x, p, v, f, starts=[True, False, False, False], substeps=2), flows, steady, path]


@case("a rig: sensors, run conditions, start states, parameter spaces")
def _rig():
    pj = _pj()
    plant = pj.presets.mas10_system("averaged")
    sensors = pj.Sensors(pressure_offset=500, pressure_gain=np.float64(1.01), delay=1e-3)
    start = pj.StartState(pressure=3e5, position=np.float32(0.01), mode="auto")
    rig = pj.Rig(plant, sensors=sensors, runs={"E": pj.RunConditions(supply_pressure=6e5, start=start)})
    both = pj.Rig(plant, sensors={"a": pj.Sensors(), "b": sensors}, runs={"E": pj.RunConditions()})
    paths = pj.parameter_paths(rig, prefix="")
    space = pj.ParameterSpace(rig, ["sensors[rig].delay", {"path": "runs[E].supply_pressure", "transform": "log"},
                                    {"path": "plant.muscle.force_law.max_force_coefficients[1]", "scale": 100.0}])
    assert "sensors[rig].delay" in paths and len(space.labels) == 3
    return [rig, both, pj.StartState(mode="stuck"), space]


@case("a small fit, its evaluation and predictions, many starts, a fleet, a staged start")
def _fit():
    import tempfile

    pj = _pj()
    start, exp = _tank_problem()
    steps = []
    res = pj.fit(start, [exp], ["volume"], max_steps=5, ftol=0, xtol=1e-10, gtol=np.float64(1e-10), stall_steps=4,
                 identifiability_tol=1e-7, progress=lambda step, cost, damping, accepted: steps.append(step))
    assert res.iterations >= 1 and steps
    with tempfile.TemporaryDirectory() as tmp:
        again = pj.FitResult.from_json(res.to_json(pathlib.Path(tmp) / "fit.json"))
    fitted = res.apply(start)
    errors, (pred,) = pj.evaluate(fitted, exp), pj.predictions(fitted, (exp,))
    assert again.values == res.values and set(errors) == {"synthetic"} and "pressure" in pred
    many = pj.multistart(start, (exp,), [{"path": "volume", "transform": "log"}], starts=2, spread=0.3, max_steps=3,
                         progress=False, distributed=False)
    fleet = pj.fit_fleet({"a": start}, {"a": exp}, ["volume"], max_steps=2, progress=False)
    staged = pj.staged_start(start, [exp], ["volume"], max_steps=3, background_compile=False)
    return [res, many, fleet, staged, pj.nuisance_report(res)]


@case("pamjax's Levenberg-Marquardt on a problem of one's own")
def _levenberg_marquardt():
    pj = _pj()
    target = np.array([1.0, 2.0])
    lm = pj.LevenbergMarquardt(ftol=0, xtol=1e-12, gtol=1e-12, stall_steps=4, geodesic=False)
    out = pj.levenberg_marquardt(lambda th: th - target, lambda th: (th - target, np.eye(2)), [0.0, 0.0],
                                 max_steps=20, solver=lm)
    again = pj.levenberg_marquardt(lambda th: th - target, lambda th: (th - target, np.eye(2)), np.zeros(2),
                                   ftol=1e-12)
    assert out.done and np.allclose(out.theta, target) and np.allclose(again.theta, target)
    return [lm, out, again]


@case("model files and a bench directory")
def _files():
    import tempfile

    pj = _pj()
    import pamjax.bench

    model = pj.presets.mas10_system("averaged", "karnopp")
    with tempfile.TemporaryDirectory() as tmp:
        path = pj.save_model(pathlib.Path(tmp) / "model.json", model, provenance={"by": "test_types"})
        back = pj.load_model(str(path), classes=())
        pj.save_model(path, back, overwrite=True)
    assert pj.parameter_paths(back) == pj.parameter_paths(model)
    bench = pamjax.bench.load_bench(ROOT / "pamjax" / "data" / "hybrid-reference-bench",
                                    pj.presets.mas10_system("pwm", "karnopp"), rate=250, kinds=["tank_charge"],
                                    nuisance=True, atmosphere=101325)
    res, _ = pj.fit(*_tank_problem(), ["volume"], max_steps=1, progress=False), None
    table = pamjax.bench.nuisance_table(pamjax.bench.bench_nuisance(res, bench))
    assert isinstance(table, str) and set(pamjax.bench.bench_rmse(res)) == {"synthetic"}
    return [back, bench]


# wrongly typed arguments: the hook names the argument before any work (no solve, no compilation)
def _wrong(name, argument, call):
    case(name, wrong=argument)(call)


_wrong("Air with a string temperature", "temperature", lambda: _pj().Air(temperature="hot"))
_wrong("OnOffValve with a number for a restriction", "inflate",
       lambda: _pj().OnOffValve(1.0, _pj().presets.mas10_silencer()))
_wrong("Muscle with a volume law for its force law", "force_law",
       lambda: _pj().Muscle(_pj().LinearVolume(1e-5, 1e-4), _pj().LinearVolume(1e-5, 1e-4), 0.0, 0.05))
_wrong("Sampled with times and values of different lengths", "values",
       lambda: _pj().Sampled(np.arange(3.0), np.ones(4)))
_wrong("a scalar parameter given a vector", "payload_mass",
       lambda: _pj().MuscleSystem(_pj().presets.mas10_valve(), _pj().presets.mas10_muscle(),
                                  payload_mass=np.ones(2)))
_wrong("mas10_system with a mistyped payload", "payload_mass", lambda: _pj().presets.mas10_system(payload_mass="9.6"))
_wrong("simulate with a string for the signal", "signal",
       lambda: _pj().simulate(_pj().presets.mas10_tank_system(), "0.5", [0.0, 0.1]))
_wrong("simulate with text tolerances", "rtol",
       lambda: _pj().simulate(_pj().presets.mas10_tank_system(), _pj().Constant(0.5), [0.0, 0.1], rtol="1e-6"))
_wrong("simulate with a 2-D array of times", "ts",
       lambda: _pj().simulate(_pj().presets.mas10_tank_system(), _pj().Constant(0.5), np.zeros((2, 2))))
_wrong("unchecked.solve with a float for the period count", "num_periods",
       lambda: _pj().unchecked.solve(_pj().presets.mas10_tank_system(), _pj().Constant(0.5), [0.0, 0.1], None, 0.0,
                                     stepping="pwm", num_periods=2.5))
_wrong("simulate_discrete with a string sample time", "sample_time",
       lambda: _pj().simulate_discrete(_pj().presets.mas10_tank_system(), _pj().Constant(0.5), "1 ms", 0.1))
_wrong("linearise with a number for the state", "state",
       lambda: _pj().linearise(_pj().presets.mas10_tank_system(), 3e5, 0.5))
_wrong("sweep with a list for over", "over",
       lambda: _pj().sweep(_pj().presets.mas10_tank_system(), _pj().Constant(0.5), [0.0, 0.1], [("signal.value", 1)]))
_wrong("sweep with an unknown gather", "gather",
       lambda: _pj().sweep(_pj().presets.mas10_tank_system(), _pj().Constant(0.5), [0.0, 0.1], {"signal.value": [1]},
                           gather="some"))
_wrong("steady_state_map with a string horizon", "horizon",
       lambda: _pj().steady_state_map(_pj().presets.mas10_tank_system(), [0.5], horizon="5 s"))
_wrong("frequency_response with a dict of frequencies", "frequencies",
       lambda: _pj().frequency_response(_pj().presets.mas10_tank_system(), {"f": 1.0}))
_wrong("flow_surface with a system for the valve", "valve",
       lambda: _pj().flow_surface(_pj().presets.mas10_tank_system(), [0.5], [3e5], _pj().Air()))
_wrong("WindowMean with a string window", "window", lambda: _pj().WindowMean("1 s"))
_wrong("ClosedLoop with a number for the controller", "controller",
       lambda: _pj().ClosedLoop(_pj().presets.mas10_system("averaged"), 25.0, _pj().Constant(0.03)))
_wrong("simulate_closed_loop with a string duration", "duration",
       lambda: _pj().simulate_closed_loop(_pj().ClosedLoop(_pj().presets.mas10_system("averaged"), _pj().PIController(),
                                                           _pj().Constant(0.03)), "1 s"))
_wrong("tune_controller with a string for the gains' names", "gains",
       lambda: _pj().tune_controller(_pj().ClosedLoop(_pj().presets.mas10_system("averaged"), _pj().PIController(),
                                                      _pj().Constant(0.03)), 1.0, 1.0))
_wrong("simulate_joint_control with a string loop", "loop", lambda: _pj().simulate_joint_control("loop", [0.0, 1.0]))
_wrong("prediction_band with a number for the result", "result",
       lambda: _pj().prediction_band(1.0, lambda m: m.temperature))
_wrong("steady_state_band with an unknown method", "method",
       lambda: _pj().steady_state_band("model.json", [0.5], method="bootstrap"))
_wrong("read_uncertainty with a number for the path", "path", lambda: _pj().read_uncertainty(3))
_wrong("fit_averaged_valve with the air first", "valve",
       lambda: _pj().fit_averaged_valve(_pj().Air(), _pj().presets.mas10_valve()))
_wrong("vppm_regulator with a number for the hysteresis", "hysteresis", lambda: _pj().vppm_regulator(hysteresis=5e3))
_wrong("muscle_stiffness with a vector of positions", "x",
       lambda: _pj().muscle_stiffness(_pj().presets.mas10_muscle(), np.zeros(3), 3e5, _pj().Air()))
_wrong("gradient_check with a string loss", "loss", lambda: _pj().gradient_check("loss", _pj().Air()))
_wrong("runtime.select_devices for an unknown kind of work", "work",
       lambda: _pj().runtime.select_devices("lanes"))
_wrong("runtime.initialize_distributed with a string timeout", "timeout",
       lambda: _pj().runtime.initialize_distributed(timeout="300"))

# the fit's entry points
_wrong("fit with one dict entry for free", "free", lambda: _pj().fit(*_tank_problem(), {"path": "volume"}))
_wrong("fit with a string progress", "progress", lambda: _pj().fit(*_tank_problem(), ["volume"], progress="yes"))
_wrong("fit with a float max_steps", "max_steps", lambda: _pj().fit(*_tank_problem(), ["volume"], max_steps=10.0))
_wrong("fit with a number for the checkpoint path", "checkpoint",
       lambda: _pj().fit(*_tank_problem(), ["volume"], checkpoint=3))
_wrong("evaluate with a number for the experiments", "experiments", lambda: _pj().evaluate(_tank_problem()[0], 3))
_wrong("predictions with a string for the experiments", "experiments",
       lambda: _pj().predictions(_tank_problem()[0], "E1"))
_wrong("multistart with a string count", "starts",
       lambda: _pj().multistart(*_tank_problem(), ["volume"], starts="8"))
_wrong("fit_fleet with a list for the fleet", "fleet",
       lambda: _pj().fit_fleet(_tank_problem()[0], [_tank_problem()[1]], ["volume"]))
_wrong("staged_start with a string max_steps", "max_steps",
       lambda: _pj().staged_start(_tank_problem()[0], [_tank_problem()[1]], ["volume"], max_steps="10"))
_wrong("Experiment with a number for the signal", "signal",
       lambda: _pj().Experiment(_pj().Recording([0.0, 0.1], {"pressure": [2e5, 3e5]}), 0.5))
_wrong("Experiment with a list of scales", "scales",
       lambda: _pj().Experiment(_pj().Recording([0.0, 0.1], {"pressure": [2e5, 3e5]}), _pj().Constant(0.5),
                                scales=[500.0]))
_wrong("Recording with a list of channels", "channels", lambda: _pj().Recording([0.0, 0.1], [[2e5, 3e5]]))
_wrong("Recording with a channel of another length", "channels",
       lambda: _pj().Recording(np.array([0.0, 0.1]), {"pressure": np.array([2e5, 3e5, 4e5])}))
_wrong("Recording.from_csv with a number for the path", "path", lambda: _pj().Recording.from_csv(3))
_wrong("ParameterSpace with a number for free", "free", lambda: _pj().ParameterSpace(_tank_problem()[0], 3))
_wrong("parameter_paths with a number for the prefix", "prefix", lambda: _pj().parameter_paths(_pj().Air(), 1))
_wrong("Rig with a list of sensors", "sensors",
       lambda: _pj().Rig(_pj().presets.mas10_system("averaged"), sensors=[_pj().Sensors()]))
_wrong("Rig with a muscle for the plant", "plant", lambda: _pj().Rig(_pj().presets.mas10_muscle()))
_wrong("Sensors with a string delay", "delay", lambda: _pj().Sensors(delay="1 ms"))
_wrong("StartState with an unknown mode", "mode", lambda: _pj().StartState(mode="sliding"))
_wrong("RunConditions with a number for the start", "start", lambda: _pj().RunConditions(start=3e5))
_wrong("synthetic_recording with a list of noise levels", "noise",
       lambda: _pj().synthetic_recording(_pj().presets.mas10_tank_system(), _pj().Constant(0.5), [0.0, 0.1],
                                         noise=[2e3]))
_wrong("LevenbergMarquardt with a string for geodesic", "geodesic", lambda: _pj().LevenbergMarquardt(geodesic="no"))
_wrong("levenberg_marquardt with a number for the residuals", "residuals",
       lambda: _pj().levenberg_marquardt(1.0, lambda th: (th, np.eye(1)), [0.0]))
_wrong("ForceMapExperiment with columns of different lengths", "pressures",
       lambda: _pj().bench.ForceMapExperiment(np.array([0.0, 0.01]), np.full(3, 3e5), np.array([10.0, 20.0])))
_wrong("HysteresisLoopExperiment with numbers for the starts", "starts",
       lambda: _pj().bench.HysteresisLoopExperiment([0.0, 0.01], [3e5, 3e5], [0.01, 0.01], [10.0, 20.0],
                                                    starts=np.array([1.0, 0.0])))
_wrong("FlowCurveExperiment with a number for the restriction", "restriction",
       lambda: _pj().bench.FlowCurveExperiment([5e5], [2e5], [1e-3], restriction=3))
_wrong("loop_average with a float for the decimals", "decimals",
       lambda: _pj().bench.loop_average([0.0], [3e5], [0.01], [10.0], decimals=2.5))
_wrong("constant_velocity_point with a 2-D force", "force",
       lambda: _pj().bench.constant_velocity_point([0.0, 0.1, 0.2], [0.0, 0.001, 0.002], np.ones((3, 2))))
_wrong("flow_curve with a string for the air", "air",
       lambda: _pj().bench.flow_curve(_pj().presets.mas10_silencer(), 5e5, [0.5], "air"))
_wrong("save_model with a number for the path", "path", lambda: _pj().save_model(3, _pj().Air()))
_wrong("load_model with a list of class names", "classes",
       lambda: _pj().load_model("model.json", classes=["MyValve"]))
_wrong("load_bench with a number for the directory", "directory",
       lambda: _pj().bench.load_bench(3, _pj().presets.mas10_system("averaged")))
_wrong("bench_rmse with a dict for the result", "result", lambda: _pj().bench.bench_rmse({"labels": []}))
_wrong("design_experiment with a string duration", "duration",
       lambda: _pj().design_experiment(_pj().presets.mas10_system("pwm"), ["volume.dead_volume"], "30 s",
                                       noise={"pressure": 2e3}))
_wrong("profile_likelihood with a dict for the result", "result", lambda: _pj().profile_likelihood({"labels": []}))


# --- the worker (a subprocess: the hook must come before pamjax's import) -------------------------------------------
def _fields_match(obj, path, seen):
    """Paths of the fields of `obj` (a dataclass or equinox Module, recursively) whose value does not match its
    annotation; named dimensions must agree between the fields of one object."""
    import jaxtyping
    from beartype.door import is_bearable

    if id(obj) in seen:
        return []
    seen.add(id(obj))
    if isinstance(obj, (list, tuple)):
        return [bad for i, x in enumerate(obj) for bad in _fields_match(x, f"{path}[{i}]", seen)]
    if isinstance(obj, dict):
        return [bad for k, x in obj.items() for bad in _fields_match(x, f"{path}[{k!r}]", seen)]
    if not (dataclasses.is_dataclass(obj) and not isinstance(obj, type)):
        return []
    import jax

    hints = typing.get_type_hints(type(obj), localns={"jax": jax})  # `jax.Device` in a module that imports JAX late
    bad = []
    with jaxtyping.jaxtyped("context"):
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            if f.name in hints and not is_bearable(value, hints[f.name]):
                shape = getattr(value, "shape", None)
                bad.append(f"{path}.{f.name}: {type(value).__name__}{'' if shape is None else list(shape)} is not "
                           f"{hints[f.name]}")
    for f in dataclasses.fields(obj):
        bad += _fields_match(getattr(obj, f.name), f"{path}.{f.name}", seen)
    return bad


def _run_case(name):
    import traceback

    import jaxtyping

    fn, wrong = CASES[name]
    try:
        built = fn()
    except jaxtyping.TypeCheckError as err:
        message = str(err)
        if wrong is None:
            return False, "a valid call was refused:\n" + message
        named = f"parameter '{wrong}'" in message
        return named, message if not named else ""
    except Exception:
        return False, traceback.format_exc()
    if wrong is not None:
        return False, f"no type error for the wrongly typed {wrong!r}"
    bad = _fields_match(built, "result", set())
    return not bad, "fields that do not match their annotations:\n" + "\n".join(bad) if bad else ""


def _worker():
    import jaxtyping

    jaxtyping.install_import_hook(CHECKED, "beartype.beartype")
    import jax

    jax.config.update("jax_enable_x64", True)
    for name in CASES:
        ok, detail = _run_case(name)
        print(json.dumps({"case": name, "ok": ok, "detail": detail}), flush=True)


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return env


_RESULTS = {}


def _results():
    if not _RESULTS:
        run = subprocess.run([sys.executable, __file__], cwd=ROOT, env=_env(), capture_output=True, text=True,
                             timeout=1200)
        for line in run.stdout.splitlines():
            if line.startswith("{"):
                entry = json.loads(line)
                _RESULTS[entry["case"]] = entry
        _RESULTS.setdefault("", {"ok": False, "detail": run.stdout[-3000:] + run.stderr[-3000:]})
    return _RESULTS


def pytest_generate_tests(metafunc):
    if "case_name" in metafunc.fixturenames:
        metafunc.parametrize("case_name", list(CASES))


def test_annotations_under_beartype(case_name):
    results = _results()
    assert case_name in results, "the worker did not report this case:\n" + results[""]["detail"]
    assert results[case_name]["ok"], results[case_name]["detail"]


# --- the field converters: a parameter is a real number (integers made floats, bools refused) -----------------------
# (pamjax imported inside the tests: this file's worker imports it only after installing the type-checking hook)
def _host_or_jax(value):
    import jax.numpy as jnp

    return jnp.asarray(10) if isinstance(value, str) else value


@pytest.mark.parametrize("value", [10, np.int64(10), np.int32(10), [1, 2], (3,), np.arange(3), [[1], [2]], "jax"])
def test_integer_parameters_become_floats_without_compiling(value, monkeypatch):
    """`payload_mass=10` was stored as int64: the README's `jax.grad(loss)(system)` failed with JAX's "grad requires
    real-valued inputs ... got int64", naming no parameter. Host values still go through without compiling."""
    import jax
    import jax.numpy as jnp

    from pamjax._core.arrays import as_array, as_scalar, as_table

    value = _host_or_jax(value)
    convert = as_scalar if np.ndim(value) == 0 else as_table if np.ndim(value) == 1 else as_array
    expected = np.asarray(value, dtype=float)
    if not isinstance(value, jax.Array):
        monkeypatch.setattr(jnp, "asarray", lambda *a, **k: pytest.fail("jnp.asarray of a host value (compiles)"))
    got = convert(value)
    monkeypatch.undo()
    assert got.dtype == jnp.float64 and got.shape == expected.shape
    assert got.weak_type == (type(value) is int)  # a Python int as a Python float: weakly typed
    np.testing.assert_array_equal(np.asarray(got), expected)


@pytest.mark.parametrize("value, what", [(True, "a bool"), (np.bool_(False), "a bool"), ([True, False], "bools")])
def test_a_bool_parameter_is_refused(value, what):
    import jax.numpy as jnp

    from pamjax import PamjaxInputError
    from pamjax._core.arrays import as_array, as_scalar

    for given in (value, jnp.asarray(value)):
        what = what if given is value else "bools"
        with pytest.raises(PamjaxInputError, match=rf"a parameter must be a number, got .* \({what}\): write the"):
            as_scalar(given) if np.ndim(given) == 0 else as_array(given)


def test_an_integer_payload_is_differentiable_and_a_bool_one_refused():
    import jax
    import jax.numpy as jnp

    import pamjax as pj
    from pamjax import PamjaxInputError, presets

    system = presets.mas10_system(valve="averaged", payload_mass=10)
    assert system.payload_mass.dtype == jnp.float64
    grad = jax.grad(lambda s: s.payload_mass ** 2 + s.friction.coulomb_force)(system)  # was a raw TypeError
    assert float(grad.payload_mass) == pytest.approx(20.0)
    friction = pj.CoulombViscousFriction(16, 250)
    assert friction.coulomb_force.dtype == friction.viscous_coefficient.dtype == jnp.float64
    with pytest.raises(PamjaxInputError, match=r"got True \(a bool\)"):
        presets.mas10_system(valve="averaged", payload_mass=True)  # was 1 kg


def test_check_overrides_names_the_closest_field_and_all_of_them():
    import pamjax as pj
    from pamjax import PamjaxInputError
    from pamjax._core.arrays import check_overrides

    check_overrides(pj.OnOffValve, {"pwm_frequency": 40.0}, "f")
    with pytest.raises(PamjaxInputError, match=r"f got the keyword supply=, which is no OnOffValve field \(did you "
                                               r"mean supply_pressure=\?\); the fields it overrides: inflate, exhaust"):
        check_overrides(pj.OnOffValve, {"supply": 6e5}, "f")
    with pytest.raises(PamjaxInputError, match=r"xyz=, which is no OnOffValve field; the fields"):
        check_overrides(pj.OnOffValve, {"xyz": 1}, "f")


if __name__ == "__main__":
    _worker()
