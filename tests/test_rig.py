"""A real rig's nuisances (`pamjax.Rig`, `Sensors`, `RunConditions`, `StartState`), bench folders as a rig logs them
(CSV in barg and mm, MAT), and what a fit without the nuisances says about them.

The sensor model is checked against its NumPy transcription on the plant simulated at t − delay; the run conditions
against `simulate` of the plant with that supply and start; the identification on a small rig written as CSV files
(supply drift, offset, gain, a fractional delay, a run logged mid-way), fitted from the presets."""

import json
import re

import equinox as eqx
import jax
import numpy as np
import pytest

import pamjax as pj
from pamjax import PamjaxInputError, presets

ATM = 101325.0
NOISE = {"p_std_Pa": 2000.0, "x_std_m": 1e-4}
TRUTH = dict(delay_s=1.7e-3, pressure_offset_Pa=1500.0, pressure_gain=1.008,
             supply={"T1": 6.3e5, "T2": 6.62e5, "M0": 6.45e5, "M1": 6.4e5})
PREROLL = 0.6  # s: M1 is logged from 0.6 s into its triangle


def _plant():
    return presets.mas10_system(valve="pwm", friction="karnopp")


def _read_at(system, signal, t_read, y0, substeps=32):
    """The plant's channels at times `t_read` (before 0: the start state), by `simulate`."""
    after = t_read > 0
    traj = pj.simulate(system, signal, np.concatenate([[0.0], t_read[after]]), y0=y0, stepping="pwm",
                       substeps=substeps)
    return {c: np.asarray(traj.channel(c))[np.cumsum(after)] for c in ("pressure", "position")
            if c in traj.channels()}


def test_sensors_delay_and_supply_match_their_numpy_transcription():
    plant = _plant()
    rec = pj.Recording(np.arange(0.0, 0.3001, 1e-3), {"pressure": np.full(301, ATM)})
    exp = pj.Experiment(rec, pj.Constant(0.5), build=pj.TankFromModel(5e-5), initial={"pressure": ATM}, name="T")
    sensors = pj.Sensors(pressure_offset=1500.0, pressure_gain=1.01, delay=1.7e-3)
    rig = pj.Rig(plant, sensors=sensors, runs={"T": pj.RunConditions(supply_pressure=6.3e5)})
    (pred,) = pj.predictions(rig, [exp])
    system = pj.TankFromModel(5e-5)(plant).with_supply_pressure(6.3e5)
    true = _read_at(system, pj.Constant(0.5), rec.t - 1.7e-3, system.initial_state(ATM), substeps=16)["pressure"]
    expected = ATM + 1.01 * (true - ATM) + 1500.0
    np.testing.assert_allclose(pred["pressure"], expected, atol=5.0)  # Pa; the fit's 16-node grid vs simulate's
    (plain,) = pj.predictions(plant, [exp])  # a plain plant: ideal sensors, nominal supply (0.65 MPa)
    assert np.max(np.abs(plain["pressure"] - pred["pressure"])) > 1e4


def test_a_start_state_and_its_sliding_mode_match_simulate():
    plant = _plant()
    t = np.arange(0.0, 0.5001, 1e-3)
    rec = pj.Recording(t, {"pressure": np.full(t.size, 4e5), "position": np.zeros(t.size)})
    signal = pj.Triangle(0.05, 0.95, 0.5)
    exp = pj.Experiment(rec, signal, name="M")
    start = pj.StartState(pressure=4.2e5, position=0.02, velocity=0.015)
    (pred,) = pj.predictions(pj.Rig(plant, runs={"M": pj.RunConditions(start=start)}), [exp])
    y0 = plant.initial_state(pressure=4.2e5, position=0.02, velocity=0.015)
    assert float(y0.friction) == 1.0  # moving up: Karnopp friction sliding up, not stuck
    ref = pj.simulate(plant, signal, t, y0=y0, stepping="pwm")
    np.testing.assert_allclose(pred["position"], np.asarray(ref.position), atol=1e-9)
    np.testing.assert_allclose(pred["pressure"], np.asarray(ref.pressure), atol=1e-3)
    with pytest.raises(PamjaxInputError, match="stuck"):
        pj.StartState(velocity=0.1, mode="stuck")


def test_parameter_paths_name_runs_and_sensors():
    rig = pj.Rig(_plant(), runs={"E1_u0.25": pj.RunConditions(supply_pressure=6.4e5),
                                 "7": pj.RunConditions(supply_pressure=6.5e5)})
    paths = pj.parameter_paths(rig)
    assert "runs[E1_u0.25].supply_pressure" in paths and "runs['7'].supply_pressure" in paths
    assert "sensors[rig].delay" in paths and "plant.friction.coulomb_force" in paths
    space = pj.ParameterSpace(rig, ["runs[E1_u0.25].supply_pressure", "sensors[rig].pressure_offset",
                                    "plant.muscle.force_law.max_force_coefficients[2]"])
    moved = space.with_values(np.asarray([6.2e5, 900.0, 1.0]))
    assert float(moved.runs["E1_u0.25"].supply_pressure) == 6.2e5
    assert float(moved.sensors["rig"].pressure_offset) == 900.0
    for bad in ("runs[].supply_pressure", "runs[E1].x[1].y", "sensors[rig]..delay"):
        with pytest.raises(PamjaxInputError, match="malformed"):
            pj.ParameterSpace(rig, [bad])
    with pytest.raises(PamjaxInputError, match="unknown parameter"):
        pj.ParameterSpace(rig, ["runs[E9].supply_pressure"])


def test_implausible_sensors_and_a_group_no_experiment_reads_are_named():
    # A gain written in percent (101.0) or a delay in ms (2.0) ran a fit to max_steps at 887x the noise; sensors
    # under a group name no experiment reads (a typo: "Rig") were not used at all: the experiments read as ideal.
    for kw, match in ((dict(pressure_gain=101.0), r"pressure_gain = 101 is outside \[0.5, 2\] \(a gain in percent"),
                      (dict(delay=2.0), r"delay = 2 is outside \[-0.1, 0.1\] \(s: a delay in ms"),
                      (dict(position_offset=-0.3), r"position_offset = -0.3 .*an offset in mm"),
                      (dict(pressure_offset=2e5), r"pressure_offset = 200000 .*kPa or bar")):
        with pytest.raises(PamjaxInputError, match=match):
            pj.Sensors(**kw)
    t = np.linspace(0.0, 0.1, 11)
    exp = pj.Experiment(pj.Recording(t, {"pressure": np.full(11, ATM)}), pj.Constant(0.5))  # group "rig"
    with pytest.raises(PamjaxInputError, match=r"reads sensor group 'rig', which the Rig has none of \(its groups: "
                                               r"\['Rig'\]\)"):
        pj.predictions(pj.Rig(_plant(), sensors={"Rig": pj.Sensors(pressure_offset=1500.0)}), [exp])


def test_a_group_the_rig_lacks_is_answered_with_the_keyword_experiment_takes():
    # the advice was Experiment(sensor_group=...), a keyword Experiment does not have (a TypeError if followed)
    t = np.linspace(0.0, 0.1, 11)
    rec = pj.Recording(t, {"pressure": np.full(11, ATM)})
    with pytest.raises(PamjaxInputError, match=r"Experiment\(\.\.\., sensors='left'\)") as info:
        pj.predictions(pj.Rig(_plant(), sensors={"left": pj.Sensors()}), [pj.Experiment(rec, pj.Constant(0.5))])
    assert "sensor_group" not in str(info.value)
    assert pj.Experiment(rec, pj.Constant(0.5), sensors="left").sensor_group == "left"  # the advice, followed


def _write_rig(folder, fmt="csv"):
    """A small rig: a tank charge T1 and a discharge T2 (0.5 s), a triangle run M0 from rest (1.2 s) and one, M1,
    logged from PREROLL s (2 s), with the nuisances of TRUTH, written as a logger writes them (time [s], duty [-],
    pressure [barg], position [mm])."""
    plant = _plant()
    truth = pj.ParameterSpace(plant, ["valve.inflate.discharge_coefficient", "friction.coulomb_force"]).with_values(
        np.asarray([0.40, 14.0]))
    rng = np.random.default_rng(7)
    period = 0.02
    runs = {"T1": ("tank_charge", pj.Constant(0.5), 0.5), "T2": ("tank_discharge", pj.Constant(0.3), 0.5),
            "M0": ("muscle_triangle", pj.Triangle(0.05, 0.95, 0.4), 1.2),
            "M1": ("muscle_triangle", pj.Triangle(0.05, 0.95, 0.5), 2.0)}
    experiments = {}
    for name, (kind, signal, t_end) in runs.items():
        t = np.arange(0.0, t_end + 5e-4, 1e-3)
        supply = TRUTH["supply"][name]
        preroll = PREROLL if name == "M1" else 0.0
        if kind.startswith("tank"):
            system = pj.TankFromModel(5e-5)(truth).with_supply_pressure(supply)
            y0 = system.initial_state(ATM if kind == "tank_charge" else supply)
            experiments[name] = dict(kind=kind, V_tank=5e-5, u=float(signal.value), p0="p_atm" if kind ==
                                     "tank_charge" else "p_s")
        else:
            system, y0 = truth.with_supply_pressure(supply), None
            experiments[name] = dict(kind=kind, lo=0.05, hi=0.95, f_tri=float(signal.frequency))
            if preroll:
                experiments[name]["init"] = "unknown: logged mid-way"
        clean = _read_at(system, signal, t + preroll - TRUTH["delay_s"], y0)
        duty = np.asarray(jax.vmap(signal)(np.floor((t + preroll) / period + 1e-9) * period))
        p = TRUTH["pressure_gain"] * (clean["pressure"] - ATM) + TRUTH["pressure_offset_Pa"] + NOISE[
            "p_std_Pa"] * rng.standard_normal(t.size)
        x = clean["position"] + NOISE["x_std_m"] * rng.standard_normal(t.size) if "position" in clean else 0 * t
        if fmt == "csv":
            np.savetxt(folder / f"{name}.csv", np.column_stack([t, duty, p / 1e5, x * 1e3]), delimiter=",",
                       header="time [s],duty [-],pressure [barg],position [mm]", comments="", fmt="%.6f")
        else:
            import scipy.io

            scipy.io.savemat(folder / f"{name}.mat", {"t": t, "u": duty, "p": p / 1e5, "x": x * 1e3})
    meta = dict(experiments=experiments, noise=NOISE, fitted_keys=["Cv12", "Fc"])
    if fmt == "mat":
        meta["units"] = {"p": "barg", "x": "mm"}
    (folder / "meta.json").write_text(json.dumps(meta))
    return folder


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    return _write_rig(tmp_path_factory.mktemp("rig"))


def test_a_rig_is_identified_with_its_nuisances_and_a_plain_fit_names_them(rig):
    plant = _plant()
    bench = pj.bench.load_bench(rig, plant, nuisance=True)
    assert any("logged 0.600 s into its triangle" in n for n in bench.notes), bench.notes
    assert set(bench.nuisance) >= {"sensors[rig].delay", "sensors[rig].pressure_gain", "runs[T2].supply_pressure",
                                   "runs[M1].start.velocity"}
    staged = pj.staged_start(bench.model, bench.experiments, bench.free, progress=False)
    res = pj.fit(staged.model, bench.experiments, bench.free, progress=False)
    assert res.status == "converged", res.message
    values = dict(zip(res.labels, res.values))
    se = dict(zip(res.labels, res.standard_errors))
    expect = {"plant.valve.inflate.discharge_coefficient": 0.40, "plant.friction.coulomb_force": 14.0,
              "sensors[rig].delay": TRUTH["delay_s"], "sensors[rig].pressure_offset": TRUTH["pressure_offset_Pa"],
              "sensors[rig].pressure_gain": TRUTH["pressure_gain"],
              **{f"runs[{n}].supply_pressure": p for n, p in TRUTH["supply"].items()}}
    for label, true in expect.items():
        assert abs(values[label] - true) < 4 * se[label] + 1e-9 * abs(true), (label, values[label], true, se[label])
    for name, chans in res.channel_errors.items():
        assert all(st["rmse_over_noise"] < 1.15 for st in chans.values()), (name, chans)
    report = pj.bench.bench_nuisance(res, bench)
    assert set(report["supply_pressure_Pa"]) == {"T1", "T2", "M0", "M1"} and set(report["start"]) == {"M1"}
    assert report["held"]["position_offset_m"].startswith("not identifiable")
    # the same data fitted as an ideal bench: the fit says what the residuals point to
    plain = pj.bench.load_bench(rig, plant)
    res0 = pj.fit(plant, plain.experiments, plain.free, progress=False, max_steps=30)
    assert res0.mismatch
    text = " | ".join(res0.diagnosis)
    for finding in ("the data lag the model", "an offset at rest", "a start that is not at rest",
                    "a supply pressure the tank runs contradict"):
        assert finding in text, text
    assert "a valve that opens" not in text, text  # a delay, a gain and supply drift are not the valve's timing
    [lag] = [f for f in res0.diagnosis if "the data lag the model" in f]  # and the lag is read as the delay it is
    assert "most likely an acquisition delay (a valve slower than the model's would" in lag, lag
    assert "--nuisance" in text


def test_a_start_already_freed_is_not_diagnosed_as_not_at_rest(rig):
    # The hint "a start that is not at rest" reads the data alone (the first 20 ms move): it names M1 (logged mid-run)
    # when the fit holds M1's start at rest, and not when the fit frees it (a rig's labels "runs[M1].start.…"; the
    # hint used to fire for those too). Predictions equal to the data: no other finding, and no solve needed.
    from pamjax._fit.rig_hints import nuisance_hints

    plant = _plant()
    plain = pj.bench.load_bench(rig, plant)
    preds = {e.name: {c: np.asarray(e.data[c]) for c in e.channels} for e in plain.experiments}
    held = " | ".join(nuisance_hints(plant, plain.experiments, preds, plain.free))
    assert "a start that is not at rest: M1" in held and "M0" not in held, held
    labels = plain.free + ["runs[M1].start.pressure", "runs[M1].start.position", "runs[M1].start.velocity"]
    assert "not at rest" not in " | ".join(nuisance_hints(plant, plain.experiments, preds, labels))
    # a run already marked "init": "unknown" gets the same hint: it told the user to add what meta.json had; now it
    # says that such a run is fitted from rest until its start is freed; a quoted run path (runs['M1']) frees it too
    assert '"init": "unknown" in meta.json (if it is not already' in held, held
    quoted = plain.free + [f"runs['M1'].start.{k}" for k in ("pressure", "position", "velocity")]
    assert "not at rest" not in " | ".join(nuisance_hints(plant, plain.experiments, preds, quoted))


def test_runs_predicted_together_equal_each_run_predicted_alone(rig):
    # A fit's runs of one system structure share one loop, and their output channels are traced once for all runs
    # (pamjax._solve.run_outputs: blocks of samples side by side, each with its run's parameters, a run's last block
    # padded). Against each run predicted alone (the one-run path, traced apart): runs of other lengths (M0 1.2 s,
    # M1 2 s, both over one block), their own supply pressures, and M1's start logged mid-way.
    bench = pj.bench.load_bench(rig, _plant(), nuisance=True)
    model = eqx.tree_at(lambda m: m.runs["M1"].supply_pressure, bench.model, 6.3e5)  # runs unlike each other
    names = [e.name for e in bench.experiments]
    together = dict(zip(names, pj.predictions(model, bench.experiments)))
    for name in ("T2", "M0", "M1"):
        [alone] = pj.predictions(model, [bench.experiments[names.index(name)]])
        assert set(alone) == set(together[name]), name
        for channel, values in alone.items():
            assert np.all(np.isfinite(values)), (name, channel)
            np.testing.assert_allclose(together[name][channel], values, rtol=1e-12, atol=1e-9, err_msg=name)


def test_signals_of_runs_stack_where_they_can():
    # pamjax._solve.run_signals: a rig's logged duties (tables of different lengths) become one signal with a run
    # axis, each table padded past its end; every run must read the same at every time, before, inside and after
    from pamjax._solve.run_signals import stacked_signals

    period = 0.02
    short = pj.Sampled(np.arange(5) * 0.013, [0.1, 0.5, 0.9, 0.3, 0.7], period=period)
    long = pj.Sampled(0.4 + np.arange(8) * 0.011, np.linspace(0.05, 0.95, 8), period=period)
    stacked = stacked_signals([short, long])
    t = np.linspace(-0.05, 5.0, 1011)  # past the padded samples (1 s apart after the end) too
    for k, alone in enumerate((short, long)):
        run = jax.tree_util.tree_map(lambda a, k=k: a[k] if eqx.is_array(a) else a, stacked)
        np.testing.assert_array_equal(jax.vmap(run)(t), jax.vmap(alone)(t))
    assert stacked_signals([short, pj.Sampled(short.times, short.values, period=0.01)]) is None  # another latch
    assert stacked_signals([short, pj.Triangle(0.05, 0.95, 0.5)]) is None  # other kinds: one trace per run
    assert stacked_signals([pj.Triangle(0.05, 0.95, 0.5), pj.Triangle(0.1, 0.9, 0.25)]) is not None


def test_grids_of_runs_traced_together_equal_each_runs_own():
    # solve_runs traces the PWM-synchronous grids of runs whose signals stack once, over the longest run's periods:
    # each run's grid must be exactly its own (other lengths, a start inside a period, other supplies)
    from pamjax._solve import synchronous

    plant = _plant()
    systems = [pj.TankFromModel(5e-5)(plant).with_supply_pressure(p) for p in (6.3e5, 6.6e5, 6.45e5)]
    signals = [pj.Sampled(np.arange(n) * 0.02, np.linspace(0.2, 0.8, n), period=0.02) for n in (30, 12, 21)]
    ts_list = [np.linspace(t0, t0 + d, 50) for t0, d in ((0.0, 0.55), (0.013, 0.2), (0.1, 0.33))]
    t0s = [ts[0] for ts in ts_list]
    sizes = [synchronous.num_periods(s.valve, t0, ts[-1]) for s, t0, ts in zip(systems, t0s, ts_list)]

    @jax.jit
    def grids(t0s, ts_list):
        return (synchronous._run_grids(systems, synchronous.stack_systems(systems).valve, signals, ts_list, t0s, "pwm",
                                         16, sizes),
                [synchronous.pwm_intervals(s.valve, u, t0, ts[-1], 16, n)
                 for s, u, ts, t0, n in zip(systems, signals, ts_list, t0s, sizes)])

    together, alone = grids(t0s, ts_list)
    assert len(set(sizes)) == 3
    for a, b in zip(together, alone):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


def test_runs_of_other_signal_kinds_predicted_together_equal_each_alone():
    # the two other paths of a fit's runs: signals of different kinds (one trace per run, not stacked) and signals of
    # one kind without tables (constants, stacked as they are); short tank runs of different lengths
    plant = _plant()

    def tank(name, signal, seconds):
        t = np.arange(0.0, seconds + 1e-9, 1e-3)
        rec = pj.Recording(t, {"pressure": np.full(t.size, ATM)})
        return pj.Experiment(rec, signal, build=pj.TankFromModel(5e-5), initial={"pressure": ATM}, name=name)

    logged = pj.Sampled(np.arange(20) * 0.02, np.linspace(0.2, 0.9, 20), period=0.02)
    a, b, c = tank("A", pj.Constant(0.5), 0.3), tank("B", logged, 0.4), tank("C", pj.Constant(0.7), 0.2)
    alone = {e.name: pj.predictions(plant, [e])[0] for e in (a, b, c)}
    for runs in ([a, b, c], [a, c]):
        for e, together in zip(runs, pj.predictions(plant, runs)):
            for channel, values in alone[e.name].items():
                np.testing.assert_allclose(together[channel], values, rtol=1e-12, atol=1e-9, err_msg=e.name)


def test_a_rig_logged_to_matlab_files_loads_as_its_csv_twin(tmp_path, rig):
    mat = _write_rig(tmp_path, fmt="mat")
    a, b = pj.bench.load_bench(rig, _plant()), pj.bench.load_bench(mat, _plant())
    for ea, eb in zip(a.experiments, b.experiments):
        assert ea.channels == eb.channels
        for c in ea.channels:
            np.testing.assert_allclose(np.asarray(ea.data[c]), np.asarray(eb.data[c]), atol=0.06 if c == "pressure"
                                       else 1e-8)


def _damaged(src, tmp_path, edit):
    import shutil

    folder = tmp_path / "bench"
    shutil.copytree(src, folder)
    edit(folder)
    return folder


def _meta_edit(change):
    def edit(folder):
        meta = json.loads((folder / "meta.json").read_text())
        change(meta)
        (folder / "meta.json").write_text(json.dumps(meta))
    return edit


def _csv_edit(name, change):
    def edit(folder):
        path = folder / f"{name}.csv"
        head, *rows = path.read_text().splitlines()
        path.write_text("\n".join(change(head, rows)) + "\n")
    return edit


DAMAGE = {
    "no recording": (lambda f: (f / "T2.csv").unlink(), "'T2' of meta.json has no recording T2.npz, T2.csv or T2.mat"),
    "two recordings": (lambda f: (f / "T2.npz").write_bytes(b""), "'T2' has 2 recordings"),
    "no meta": (lambda f: (f / "meta.json").unlink(), "has no meta.json.*holds 4 recording"),
    "bad json": (lambda f: (f / "meta.json").write_text("{"), "not valid JSON"),
    "duty in percent": (_meta_edit(lambda m: m["experiments"]["T1"].update(u=50)), "T1.*u = 50.*not 50 %"),
    "duty contradicts": (_meta_edit(lambda m: m["experiments"]["T1"].update(u=0.75)), "u = 0.75, but its recording"),
    "half a triangle": (_meta_edit(lambda m: m["experiments"]["M1"].pop("lo")), r"without \['lo'\].*muscle_run"),
    "wrong triangle": (_meta_edit(lambda m: m["experiments"]["M1"].update(f_tri=0.3)),
                       "not meta.json's triangle.*at any phase"),
    "mid-way at rest": (_meta_edit(lambda m: m["experiments"]["M1"].pop("init")), "logged from the middle.*unknown"),
    "payload of no mass": (_meta_edit(lambda m: m["experiments"]["M0"].update(payload_kg=0)),
                           "M0: payload_kg must be > 0 .kg."),
    "payload as text": (_meta_edit(lambda m: m["experiments"]["M0"].update(payload_kg="20 kg")),
                        "M0: payload_kg must be a number .kg., got '20 kg'"),
    "payload on a tank": (_meta_edit(lambda m: m["experiments"]["T1"].update(payload_kg=20)),
                          "'T1' is a tank test, which lifts no payload"),
    "zero noise": (_meta_edit(lambda m: m["noise"].update(p_std_Pa=0)), "p_std_Pa must be.*> 0"),
    "unqualified bar": (_csv_edit("T1", lambda h, r: [h.replace("barg", "bar"), *r]), "ABSOLUTE or GAUGE"),
    "NaN": (_csv_edit("T1", lambda h, r: [h, *r[:5], "0.005,0.5,nan,0", *r[6:]]), "NaN/inf at row 5"),
    "unsorted": (_csv_edit("T1", lambda h, r: [h, r[1], r[0], *r[2:]]), "strictly increasing"),
    "gauge without its uncertainty": (_meta_edit(lambda m: m["experiments"]["T1"].update(supply_Pa=6.3e5)),
                                      "T1: a supply reading needs supply_Pa .* and supply_sd_Pa"),
    "gauge read as gauge": (_meta_edit(lambda m: m["experiments"]["T2"].update(supply_Pa=5.61e5, supply_sd_Pa=1e3)),
                            r"T2: supply_Pa = 561000 Pa lies below the run's recorded pressure .* ABSOLUTE"),
    "gauge in bar": (_meta_edit(lambda m: m["experiments"]["T1"].update(supply_Pa=6.3, supply_sd_Pa=0.01)),
                     r"T1: supply_Pa = 6.3 is outside \[50000.0, 5000000.0\]"),
    "a coarse sensor, its noise not given": (  # positions logged in whole mm: the noise cannot be estimated
        lambda f: [_meta_edit(lambda m: m.pop("noise"))(f)] + [
            _csv_edit(n, lambda h, r: [h, *[",".join(c.split(",")[:3] + [str(round(float(c.split(",")[3])))])
                                            for c in r]])(f) for n in ("M0", "M1")],
        r"the position noise cannot be estimated .* 'noise': \{\"x_std_m\": ...\} \[m\]"),
}


@pytest.mark.parametrize("case", sorted(DAMAGE))
def test_every_mistake_in_a_bench_folder_is_named_before_any_fit(case, rig, tmp_path):
    edit, message = DAMAGE[case]
    folder = _damaged(rig, tmp_path, edit)
    with pytest.raises(PamjaxInputError, match=message):
        pj.bench.load_bench(folder, _plant(), nuisance=True)


@pytest.mark.parametrize("start", [1234.5, 1234.507])
def test_a_logger_clock_that_does_not_start_at_zero_reads_as_the_same_rig(rig, tmp_path, start):
    # A data-acquisition clock at 1234.5 s when the runs start: the triangle's phase is counted from each recording's
    # first sample (was: M0, started at rest, refused as "logged from the middle ... 0.500 s in"); the residuals are
    # the same as the zero-based files'. At 1234.507 s the clock is 7 ms off the 20 ms PWM periods too: the valve
    # switched 7 ms off the recorded edges (a tank charge's residuals at 11x the noise); the periods are now put where
    # the recorded duty changes (M0, M1) or at the first sample (the tanks' constant duty), said in the notes.
    def shift(folder):
        for path in folder.glob("*.csv"):
            head, *rows = path.read_text().splitlines()
            path.write_text("\n".join([head] + [f"{float(r.split(',', 1)[0]) + start:.6f},{r.split(',', 1)[1]}"
                                               for r in rows]) + "\n")

    zero = pj.bench.load_bench(rig, _plant(), nuisance=True)
    late = pj.bench.load_bench(_damaged(rig, tmp_path, shift), _plant(), nuisance=True)
    moved = [n for n in late.notes if "onto the valve's clock" in n]
    assert [n for n in late.notes if n not in moved] == zero.notes  # M0 checked at rest, M1 mid-way at the same phase
    assert len(moved) == (0 if start == 1234.5 else 4), moved
    assert any("M0: recorded duty = meta.json's triangle (checked)" in n for n in late.notes)
    # every run's predictions in one compiled program (as a fit makes them), not one program per run
    for a, b, pa, pb in zip(zero.experiments, late.experiments, pj.predictions(zero.model, zero.experiments),
                            pj.predictions(late.model, late.experiments)):
        np.testing.assert_allclose(np.asarray(b.residuals_of(pb)), np.asarray(a.residuals_of(pa)), rtol=1e-7,
                                   atol=1e-7)


def test_supply_readings_of_a_reference_gauge_are_fitted_as_measurements(rig, tmp_path):
    folder = _damaged(rig, tmp_path, _meta_edit(lambda m: (m["experiments"]["T1"].update(supply_Pa=6.31e5,
                                                                                         supply_sd_Pa=1e3),
                                                           m["experiments"]["M0"].update(supply_Pa=6.44e5,
                                                                                         supply_sd_Pa=2e3))))
    bench = pj.bench.load_bench(folder, _plant(), nuisance=True)
    gauges = [e for e in bench.experiments if isinstance(e, pj.Measurement)]
    assert [(g.name, g.path, g.value, g.sd) for g in gauges] == [
        ("gauge: T1 supply", "runs[T1].supply_pressure", 6.31e5, 1e3),
        ("gauge: M0 supply", "runs[M0].supply_pressure", 6.44e5, 2e3)]
    start = dict(zip(*[pj.ParameterSpace(bench.model, bench.free).labels,
                       pj.ParameterSpace(bench.model, bench.free).initial_values()]))
    assert start["runs[T1].supply_pressure"] == 6.31e5 and start["runs[M0].supply_pressure"] == 6.44e5
    assert any("read by a reference gauge" in n and "T1, M0" in n for n in bench.notes), bench.notes
    plain = pj.bench.load_bench(folder, _plant())  # supplies not freed: the readings are said to be unused
    assert not any(isinstance(e, pj.Measurement) for e in plain.experiments)
    assert any("T1, M0: supply pressures read by a reference gauge" in n and "unused" in n for n in plain.notes)
    # the report: each supply beside its reading, and no gauge among the recordings' RMSEs (also read from JSON)
    report = dict(delay_s=1e-3, pressure_offset_Pa=100.0, pressure_gain=1.0, position_offset_m=0.0, start={}, held={},
                  supply_pressure_Pa={"T1": 6.325e5},
                  std_err={"delay_s": 1e-6, "pressure_offset_Pa": 30.0, "pressure_gain": 4e-4,
                           "supply_pressure_Pa": {"T1": 800.0}},
                  gauges={"T1": {"supply_Pa": 6.31e5, "supply_sd_Pa": 1e3, "z": 1.5}})
    assert "(T1)  (gauge 631000 ± 1e+03, fitted +1.50 of its uncertainties from it)" in pj.bench.nuisance_table(report)
    import types

    stored = types.SimpleNamespace(experiments=None, channel_errors={
        "T1": {"pressure": {"rmse": 2e3}}, "gauge: T1 supply": {"value": {"rmse": 1.5e3, "z": 1.5}}})
    assert pj.bench.bench_rmse(stored) == {"T1": {"p": 2e3}}


def test_joint_script_answers_a_bad_folder_in_one_line_and_leaves_nothing(rig, tmp_path, capsys):
    import importlib.util
    import pathlib

    spec = importlib.util.spec_from_file_location("joint", pathlib.Path(__file__).parents[1] / "fits" / "joint.py")
    joint = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(joint)
    folder = _damaged(rig, tmp_path, DAMAGE["duty in percent"][0])
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_:
        joint.main(["--data", str(folder), "--out", str(out), "--nuisance", "--no-cache"])
    assert exit_.value.code == 2 and not out.exists()
    err = capsys.readouterr().err
    assert err.startswith("joint.py: error:") and "u = 50" in err and "Traceback" not in err


def test_pamjax_fit_with_bench_nuisance_writes_the_plant_and_the_rig_apart(rig, tmp_path, capsys):
    from pamjax._cli.main import main

    cfg = tmp_path / "rig.toml"
    body = ('[model]\npreset = "mas10_system"\noptions = { valve = "pwm", friction = "karnopp" }\n'
            f'[bench]\ndir = "{rig}"\nnuisance = NUISANCE\n[fit]\nmax_steps = 100\n')
    cfg.write_text(body.replace("NUISANCE", "true"))
    assert main(["fit", str(cfg), "--out", str(tmp_path / "out"), "--quiet", "--no-plot"]) == 0
    out = capsys.readouterr().out
    assert "nuisances (the rig's, reported apart from the plant)" in out and "delay_s" in out
    bench = json.loads((tmp_path / "out" / "bench.json").read_text())
    assert bench["status"] == "converged" and set(bench["nuisance"]["supply_pressure_Pa"]) == set(TRUTH["supply"])
    assert abs(bench["nuisance"]["delay_s"] - TRUTH["delay_s"]) < 4 * bench["nuisance"]["std_err"]["delay_s"]
    plant = pj.load_model(tmp_path / "out" / "model.json")  # the plant alone: simulate it, fit it again
    assert isinstance(plant, pj.MuscleSystem)
    assert abs(float(plant.friction.coulomb_force) - 14.0) < 4 * bench["std_err"]["Fc"]
    cfg.write_text(body.replace("NUISANCE", '"all"'))
    assert main(["fit", str(cfg), "--out", str(tmp_path / "bad"), "--quiet", "--no-plot"]) == 2
    assert "[bench] nuisance" in capsys.readouterr().err


def test_a_config_declares_the_rig_of_its_experiments(rig, tmp_path, capsys):
    # [rig]: the sensors' start values and which nuisances to fit; each [[experiment]] its supply pressure (and a
    # start table for a run logged mid-way). Here the delay and the offset are fitted with the valve's C_v 1→2.
    from pamjax._cli.main import main

    tanks = "".join(
        f'[[experiment]]\nname = "{n}"\nfile = "{rig / (n + ".csv")}"\nsignal = "recorded"\ntank_volume = 5e-5\n'
        f'initial = {{ pressure = {p0} }}\nchannels = ["pressure"]\nscales = {{ pressure = 2000.0 }}\n'
        f'supply_pressure = {TRUTH["supply"][n]}\n' for n, p0 in (("T1", ATM), ("T2", TRUTH["supply"]["T2"])))
    cfg = tmp_path / "rig.toml"
    head = ('[model]\npreset = "mas10_system"\noptions = { valve = "pwm", friction = "karnopp" }\n'
            '[fit]\nfree = ["valve.inflate.discharge_coefficient"]\nmax_steps = 60\n')
    cfg.write_text(head + f'[rig]\nsensors = {{ pressure_gain = {TRUTH["pressure_gain"]} }}\n'
                          'free = ["delay", "pressure_offset"]\n' + tanks)
    assert main(["fit", str(cfg), "--out", str(tmp_path / "out"), "--quiet", "--no-plot"]) == 0
    assert "sensors[rig].delay" in capsys.readouterr().out
    res = pj.FitResult.from_json(tmp_path / "out" / "fit.json")
    got = dict(zip(res.labels, zip(res.values, res.standard_errors)))
    assert res.status == "converged", res.message
    for label, true in (("sensors[rig].delay", TRUTH["delay_s"]), ("sensors[rig].pressure_offset",
                                                                  TRUTH["pressure_offset_Pa"])):
        assert abs(got[label][0] - true) < 4 * got[label][1], (label, got[label], true)
    assert abs(got["plant.valve.inflate.discharge_coefficient"][0] - 0.40) < 4 * got[
        "plant.valve.inflate.discharge_coefficient"][1]
    cfg.write_text(head + '[rig]\nfree = ["gain"]\n' + tanks)
    assert main(["fit", str(cfg), "--out", str(tmp_path / "bad"), "--quiet", "--no-plot"]) == 2
    assert "[rig] free names ['gain']" in capsys.readouterr().err
    # a sensors group no experiment reads (its calibration would do nothing), a gain in percent: named, nothing fitted
    for rig_table, match in (('sensors = { left = { pressure_offset = 1500.0 } }\nfree = ["delay"]',
                              "[rig] sensors: no [[experiment]] reads its sensors as ['left'] (their groups: ['rig']"),
                             ('sensors = { pressure_gain = 100.8 }\nfree = ["delay"]',
                              "[rig] sensors: Sensors.pressure_gain = 100.8 is outside [0.5, 2] (a gain in percent")):
        cfg.write_text(head + f"[rig]\n{rig_table}\n" + tanks)
        assert main(["fit", str(cfg), "--out", str(tmp_path / "bad"), "--quiet", "--no-plot"]) == 2
        assert match in capsys.readouterr().err


def test_a_failing_stage_waits_for_the_background_compilation(rig, monkeypatch):
    # The second thread compiling the joint problem must not outlive an error of stage 1: XLA compiling in a thread
    # while the interpreter shuts down killed fits/joint.py (exit 139/134) after a data error.
    import threading
    import time

    from pamjax._fit import staged as staged_module

    started, threads = threading.Event(), []

    def slow_precompile(model, experiments, free):
        threads.append(threading.current_thread())
        started.set()
        time.sleep(0.5)
        return 0.5

    def failing_fit(*args, **kwargs):
        started.wait()
        raise PamjaxInputError("stage 1 failed")

    monkeypatch.setattr(staged_module, "precompile", slow_precompile)
    monkeypatch.setattr(staged_module, "fit", failing_fit)
    bench = pj.bench.load_bench(rig, _plant(), nuisance=True)
    with pytest.raises(PamjaxInputError, match="stage 1 failed"):
        pj.staged_start(bench.model, bench.experiments, bench.free)
    assert threads and not threads[0].is_alive()


def test_the_staged_start_holds_the_position_offset_for_the_joint_fit(rig):
    # From the presets no model run rests on a stop, so the stages would wander along the offset's near-null
    # direction (an unseen rig: -9.3 mm for +0.06): they hold it at its start value; the joint problem fits it.
    # A calibrated gain with its uncertainty (a pamjax.Measurement) goes with its parameter: stage 1 (the tank tests).
    bench = pj.bench.load_bench(rig, _plant(), nuisance=["delay", "position_offset"], position_offset=2e-5,
                                pressure_gain=1.007, pressure_gain_sd=1e-3)
    assert "sensors[rig].position_offset" in bench.free
    assert bench.experiments[-1].name == pj.bench.CALIBRATION_NAME
    staged = pj.staged_start(bench.model, bench.experiments, bench.free, max_steps=2, progress=False,
                             background_compile=False)
    assert [name for name, *_ in staged.stages] == ["1", "2"]
    staged_paths = [p for _, paths, _, _ in staged.stages for p in paths]
    assert "sensors[rig].position_offset" not in staged_paths
    assert {"sensors[rig].delay", "plant.friction.coulomb_force"} <= set(staged_paths)
    assert float(staged.model.sensors["rig"].position_offset) == 2e-5
    (_, paths1, exps1, res1), (_, paths2, exps2, _) = staged.stages
    assert "sensors[rig].pressure_gain" in paths1 and {"T1", "T2", pj.bench.CALIBRATION_NAME} == set(exps1)
    assert "sensors[rig].pressure_gain" not in paths2 and pj.bench.CALIBRATION_NAME not in exps2
    assert set(res1.channel_errors[pj.bench.CALIBRATION_NAME]["value"]) >= {"measured", "sd", "fitted", "z"}


def test_a_calibrated_pressure_gain_is_held_or_is_the_start_of_its_fit(rig, tmp_path):
    # With every run's supply free the recordings fix the gain to ~0.3 % only (benchmarks/RESULTS.md, identify); a
    # calibration the user gives is held (nuisance=True frees the others), or is the start value where named.
    held = pj.bench.load_bench(rig, _plant(), nuisance=True, pressure_gain=1.004)
    assert "sensors[rig].pressure_gain" not in held.free
    assert {"sensors[rig].delay", "sensors[rig].pressure_offset", "runs[T1].supply_pressure"} <= set(held.free)
    assert float(held.model.sensors["rig"].pressure_gain) == 1.004 and held.calibrated == {"pressure_gain": 1.004}
    assert any("gain: 1.004 as calibrated, held" in n for n in held.notes), held.notes
    named = pj.bench.load_bench(rig, _plant(), nuisance=["pressure_gain", "delay"], pressure_gain=1.004)
    assert "sensors[rig].pressure_gain" in named.free
    assert pj.ParameterSpace(named.model, ["sensors[rig].pressure_gain"]).initial_values()[0] == 1.004
    alone = pj.bench.load_bench(rig, _plant(), pressure_gain=0.996)  # no nuisance freed: a rig of the calibration
    assert isinstance(alone.model, pj.Rig) and not alone.nuisance
    assert float(alone.model.sensors["rig"].pressure_gain) == 0.996
    for bad in (14.5, 0.069, float("nan"), "1.0", True):
        with pytest.raises(PamjaxInputError, match="pressure_gain must be the pressure sensor's calibrated gain"):
            pj.bench.load_bench(rig, _plant(), nuisance=True, pressure_gain=bad)
    # the pamjax command's [bench] table passes it on
    from pamjax._cli.fit import load

    cfg = tmp_path / "rig.toml"
    cfg.write_text('[model]\npreset = "mas10_system"\noptions = { valve = "pwm", friction = "karnopp" }\n'
                   f'[bench]\ndir = "{rig}"\nnuisance = true\npressure_gain = 1.004\n')
    setup = load(cfg)
    assert setup.bench.calibrated == {"pressure_gain": 1.004} and "sensors[rig].pressure_gain" not in setup.free


def test_a_calibrated_gain_with_its_uncertainty_is_fitted_with_the_calibration_as_a_measurement(rig, tmp_path):
    bench = pj.bench.load_bench(rig, _plant(), nuisance=True, pressure_gain=1.004, pressure_gain_sd=5e-4)
    assert "sensors[rig].pressure_gain" in bench.free
    assert bench.calibrated == {"pressure_gain": 1.004, "pressure_gain_sd": 5e-4}
    m = bench.experiments[-1]
    assert isinstance(m, pj.Measurement) and (m.path, m.value, m.sd) == ("sensors[rig].pressure_gain", 1.004, 5e-4)
    assert [e.name for e in bench.experiments[:-1]] == ["T1", "T2", "M0", "M1"]
    assert any("1.004 ± 0.0005 as calibrated, fitted with the recordings" in n for n in bench.notes), bench.notes
    assert pj.ParameterSpace(bench.model, ["sensors[rig].pressure_gain"]).initial_values()[0] == 1.004
    alone = pj.bench.load_bench(rig, _plant(), pressure_gain=1.004, pressure_gain_sd=5e-4)  # the gain alone freed
    assert alone.nuisance == ["sensors[rig].pressure_gain"] and alone.experiments[-1].name == m.name
    with pytest.raises(PamjaxInputError, match="pressure_gain_sd is the uncertainty of a calibrated gain: give "
                                               "pressure_gain too"):
        pj.bench.load_bench(rig, _plant(), nuisance=True, pressure_gain_sd=5e-4)
    for bad in (0.0, -1e-3, 0.5, float("nan"), "5e-4", True):
        with pytest.raises(PamjaxInputError, match="pressure_gain_sd must be the calibration's standard uncertainty"):
            pj.bench.load_bench(rig, _plant(), nuisance=True, pressure_gain=1.004, pressure_gain_sd=bad)
    # the nuisance table says where the fit put the gain against its calibration
    report = dict(delay_s=1e-3, pressure_offset_Pa=100.0, pressure_gain=1.0052, position_offset_m=0.0,
                  supply_pressure_Pa={}, start={}, held={}, std_err={"delay_s": 1e-6, "pressure_offset_Pa": 30.0,
                                                                      "pressure_gain": 4.8e-4},
                  calibration={"pressure_gain": 1.004, "pressure_gain_sd": 5e-4, "z": 2.4})
    assert "(calibrated 1.004 ± 0.0005, fitted +2.40 of its uncertainties from it)" in pj.bench.nuisance_table(report)
    # the pamjax command: [bench] pressure_gain_sd, and a [[measurement]] table of any free parameter
    from pamjax._cli.fit import load

    cfg = tmp_path / "rig.toml"
    head = '[model]\npreset = "mas10_system"\noptions = { valve = "pwm", friction = "karnopp" }\n'
    cfg.write_text(head + f'[bench]\ndir = "{rig}"\nnuisance = true\npressure_gain = 1.004\n'
                   'pressure_gain_sd = 5e-4\n[[measurement]]\npath = "runs[M0].supply_pressure"\nvalue = 6.45e5\n'
                   'sd = 1e3\nname = "gauge M0"\n')
    setup = load(cfg)
    assert [e.name for e in setup.experiments][-2:] == [pj.bench.CALIBRATION_NAME, "gauge M0"]
    assert setup.experiments[-1].value == 6.45e5 and "sensors[rig].pressure_gain" in setup.free
    for body, message in (
            ('[[measurement]]\npath = "runs[M0].supply_pressure"\nvalue = 6.45e5\n', "needs 'sd'"),
            ('[[measurement]]\npath = "runs[M9].supply_pressure"\nvalue = 6.45e5\nsd = 1e3\n',
             r"\[\[measurement\]\] #1: measured runs\[M9\].supply_pressure: the model has no parameter"),
            ('[[measurement]]\npath = "runs[M0].supply_pressure"\nvalue = 6.45e5\nsd = -1.0\n', "sd")):
        cfg.write_text(head + f'[bench]\ndir = "{rig}"\nnuisance = true\n' + body)
        with pytest.raises(PamjaxInputError, match=message):
            load(cfg)


@pytest.mark.parametrize("gain_se, hint", [(0.0035, True), (0.0005, False)])
def test_the_nuisance_table_says_what_a_loose_gain_means(gain_se, hint):
    report = dict(delay_s=1e-3, pressure_offset_Pa=100.0, pressure_gain=1.0, position_offset_m=0.0,
                  supply_pressure_Pa={"E1": 6.5e5}, start={}, held={"position_offset_m": "held at 0"},
                  std_err={"delay_s": 1e-6, "pressure_offset_Pa": 30.0, "pressure_gain": gain_se,
                           "supply_pressure_Pa": {"E1": 2e3}, "start": {}})
    table = pj.bench.nuisance_table(report)
    assert ("(± 0.35 %: each supply pressure and F_max follow its error" in table) is hint, table
    assert ("--pressure-gain" in table) is hint


@pytest.mark.parametrize("level_mm, freed, gain", [(0.1, True, None), (-0.25, True, None), (0.7, False, None),
                                                   (0.1, True, 1.003)])
def test_the_position_offset_is_freed_only_where_a_run_rests_on_a_stroke_limit(tmp_path, level_mm, freed, gain):
    # A payload still within 0.3 mm of a stroke limit rests on it (the offset shows there: freed); one 0.7 mm from it
    # may as well hang short of it, held by friction (an unseen rig did: freeing the offset there moved F_max by
    # 3.9 %), so the offset stays held and a note names the level and how to free it.
    plant = _plant()
    stop = float(plant.muscle.min_position)
    t = np.arange(0.0, 1.0005, 1e-3)
    rng = np.random.default_rng(3)
    x = stop + level_mm * 1e-3 + NOISE["x_std_m"] * rng.standard_normal(t.size)
    p = NOISE["p_std_Pa"] * rng.standard_normal(t.size)  # gauge: the valve stays shut
    np.savetxt(tmp_path / "M.csv", np.column_stack([t, 0 * t, p / 1e5, x * 1e3]), delimiter=",",
               header="time [s],duty [-],pressure [barg],position [mm]", comments="", fmt="%.6f")
    (tmp_path / "meta.json").write_text(json.dumps(dict(experiments={"M": {"kind": "muscle_run"}}, noise=NOISE,
                                                        fitted_keys=["Fc"])))
    bench = pj.bench.load_bench(tmp_path, plant, nuisance=True, pressure_gain=gain)  # a calibrated gain: the same
    assert ("sensors[rig].position_offset" in bench.free) is freed
    notes = " ".join(bench.notes)
    assert ("mm from a stroke limit" in notes) is (not freed)
    if not freed:
        assert "+0.70 mm" in notes  # the rest level, as the sensor reads it


def test_a_run_with_another_payload_is_simulated_with_it(tmp_path):
    """A muscle run made with 25 kg on the hook (meta.json `payload_kg`): its experiment simulates the plant lifting
    25 kg (`pamjax.PayloadFromModel`), and the plant that recorded it scores it at the noise; read as a 9.6 kg run,
    it is far off. The other runs keep the model's payload."""
    plant = _plant()
    heavy = eqx.tree_at(lambda m: m.payload_mass, plant, 25.0)
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 2.0 + 5e-4, 1e-3)
    signal = pj.Triangle(0.05, 0.95, 0.5)
    clean = _read_at(heavy, signal, t, None)
    duty = np.asarray(jax.vmap(signal)(np.floor(t / 0.02 + 1e-9) * 0.02))
    p = clean["pressure"] - ATM + NOISE["p_std_Pa"] * rng.standard_normal(t.size)
    x = clean["position"] + NOISE["x_std_m"] * rng.standard_normal(t.size)
    assert np.ptp(clean["position"]) > 0.01  # the payload moves
    for name in ("H", "L"):
        np.savetxt(tmp_path / f"{name}.csv", np.column_stack([t, duty, p / 1e5, x * 1e3]), delimiter=",",
                   header="time [s],duty [-],pressure [barg],position [mm]", comments="", fmt="%.6f")
    runs = dict(kind="muscle_triangle", lo=0.05, hi=0.95, f_tri=0.5)
    meta = dict(experiments={"H": dict(runs, payload_kg=25), "L": runs}, noise=NOISE, fitted_keys=["Fc"])
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    bench = pj.bench.load_bench(tmp_path, plant)
    by_name = {e.name: e for e in bench.experiments}
    assert float(by_name["H"].system_for(plant).payload_mass) == 25.0
    assert float(by_name["L"].system_for(plant).payload_mass) == float(plant.payload_mass)
    assert any("H: payload 25 kg" in n for n in bench.notes), bench.notes
    errors = pj.evaluate(plant, bench.experiments)
    for c, sigma in (("pressure", NOISE["p_std_Pa"]), ("position", NOISE["x_std_m"])):
        assert errors["H"][c]["rmse"] < 1.2 * sigma, errors["H"][c]
        assert errors["L"][c]["rmse"] > 5 * sigma, errors["L"][c]
    with pytest.raises(PamjaxInputError, match="PayloadFromModel.mass"):
        pj.PayloadFromModel(-1.0)
    with pytest.raises(PamjaxInputError, match="lifts no payload"):
        pj.PayloadFromModel(20.0)(pj.TankFromModel(5e-5)(plant))


def test_the_advised_payload_is_half_the_pull_at_zero_contraction_and_supply_pressure():
    """`PayloadFromModel.advised`: PAYLOAD_SHARE (one half) of eq. 7 at x = 0 and the supply pressure (F = a0 −
    (p_max − p_g) k0/k2, transcribed here), over g; it follows the model's force law and supply. Refused, by name,
    for a system without a payload."""
    plant = _plant()
    law, air = plant.muscle.force_law, plant.air
    for supply in (6.5e5, 5.0e5):
        model = plant.with_supply_pressure(supply)
        gauge = supply - float(air.atmospheric_pressure)
        force = float(law.max_force_coefficients[0]) - (float(law.max_pressure) - gauge) * float(law.k0) / float(
            law.k2)
        advised = pj.PayloadFromModel.advised(model)
        assert float(advised.mass) == pytest.approx(0.5 * force / float(model.gravity), rel=1e-12)
        assert float(advised(model).payload_mass) == float(advised.mass)
    with pytest.raises(PamjaxInputError, match="PayloadFromModel.advised: TankSystem lifts no payload"):
        pj.PayloadFromModel.advised(pj.TankFromModel(5e-5)(plant))


def _one_triangle_bench(folder, truth, offset=0.0):
    """A bench folder with one 1 s run of E3's triangle (duty 0.05 → at 0.08 Hz, from rest) of `truth`, noise seeded."""
    folder.mkdir()
    t = np.arange(0.0, 1.0 + 5e-4, 1e-3)
    signal = pj.Triangle(0.05, 0.95, 0.08)
    clean = _read_at(truth, signal, t, None)
    rng = np.random.default_rng(3)
    period = 1.0 / float(truth.valve.pwm_frequency)
    duty = np.asarray(jax.vmap(signal)(np.floor(t / period + 1e-9) * period))
    p = clean["pressure"] + offset + NOISE["p_std_Pa"] * rng.standard_normal(t.size)
    x = clean["position"] + NOISE["x_std_m"] * rng.standard_normal(t.size)
    np.savetxt(folder / "E3.csv", np.column_stack([t, duty, p, x]), delimiter=",",
               header="t [s],duty [-],pressure [Pa],position [m]", comments="", fmt="%.10g")
    meta = dict(experiments={"E3": dict(kind="muscle_triangle", lo=0.05, hi=0.95, f_tri=0.08)}, noise=NOISE,
                fitted_keys=["Fc"])
    (folder / "meta.json").write_text(json.dumps(meta))
    return folder


def test_a_valve_faster_or_slower_than_the_models_is_named_and_not_taken_for_a_sensor_offset(tmp_path):
    # A plant whose valve switches in 1.67 ms instead of the model's 2 ms opens at a lower duty (its thresholds are the
    # switching time over the PWM period), so on E3's triangle its pressure rises while the model still rests; the hint
    # read that as a pressure sensor offset (+3.7 kPa on a held-back plant of benchmarks/design_unseen.py) and its
    # lead of 0.34 ms as an acquisition delay, which can only lag. A 2.4 ms valve opens at duty 0.12: its data still
    # rest where the model's pressure rises. A true offset on the same run is still named.
    from pamjax._fit.rig_hints import _lag_hint, nuisance_hints

    model = _plant()
    fast = eqx.tree_at(lambda m: (m.valve.switch_on_delay, m.valve.switch_off_delay), model, (1.67e-3, 1.67e-3))
    slow = eqx.tree_at(lambda m: (m.valve.switch_on_delay, m.valve.switch_off_delay), model, (2.4e-3, 2.4e-3))
    for name, truth, offset in (("fast", fast, 0.0), ("slow", slow, 0.0), ("offset", model, 3000.0)):
        bench = pj.bench.load_bench(_one_triangle_bench(tmp_path / name, truth, offset), model)
        e = bench.experiments[0]
        pred = _read_at(model, pj.Triangle(0.05, 0.95, 0.08), np.asarray(e.times), None)
        text = " | ".join(nuisance_hints(model, bench.experiments, {e.name: pred}, bench.free))
        if name == "fast":
            assert "a valve that opens before the model's" in text and "valve.switch_on_delay" in text, text
            assert "the data lead the model" in text and "not an acquisition delay" in text, text
            assert "an offset at rest" not in text and '"t_on", "t_off"' in text, text
            keyed = pj.bench.load_bench(tmp_path / name, model, fitted_keys=["Fc", "t_on", "t_off"])
            assert keyed.free == ["friction.coulomb_force", "valve.switch_on_delay", "valve.switch_off_delay"]
        elif name == "slow":  # opens at duty 0.12, the model at 0.1: its data still rest where the model's rise
            assert "a valve that opens after the model's" in text and '"t_on", "t_off"' in text, text
            assert "an offset at rest" not in text and "opens before" not in text, text
            # its later edges make the data lag the model like an acquisition delay: the lag names the valve too
            [lag] = [f for f in text.split(" | ") if "the data lag the model" in f]
            assert "a valve that switches up to" in lag and "slower than the model's" in lag, lag
            # without a run from rest to check the valve's thresholds, the lag names both causes
            [both] = _lag_hint(4e-4, 1e-5, model, None)
            assert "an acquisition delay, or a valve that switches 0.40 ms slower" in both, both
        else:
            assert "an offset at rest" in text and "opens before" not in text and "opens after" not in text, text


def _bench_config(rig, tmp_path, body=""):
    cfg = tmp_path / "rig.toml"
    cfg.write_text('[model]\npreset = "mas10_system"\noptions = { valve = "pwm", friction = "karnopp" }\n'
                   f'[bench]\ndir = "{rig}"\nnuisance = true\n' + body)
    return cfg


def test_fit_free_beside_bench_nuisance_frees_the_nuisances_too(rig, tmp_path):
    # Was: [fit] free replaced the bench's free list, so `nuisance = true` held every nuisance, silently.
    from pamjax._cli.fit import load

    setup = load(_bench_config(rig, tmp_path, '[fit]\nfree = ["plant.friction.coulomb_force"]\n'))
    assert setup.bench.nuisance and "runs[M1].start.position" in setup.bench.nuisance
    assert setup.free == ["plant.friction.coulomb_force", *setup.bench.nuisance]
    assert any("[fit] free: the nuisances [bench] frees are fitted beside it" in n for n in setup.bench.notes)
    both = load(_bench_config(rig, tmp_path, '[fit]\nfree = ["plant.friction.coulomb_force", '
                                             '"sensors[rig].delay"]\n'))  # one already named: not twice
    assert both.free.count("sensors[rig].delay") == 1 and len(both.free) == len(setup.free)


def test_an_experiment_with_initial_beside_a_bench_rig_is_checked_against_its_plant(rig, tmp_path):
    # Was: AttributeError "'Rig' object has no attribute 'valve'" (its `initial` checked against the tank of the rig).
    from pamjax._cli.fit import load

    extra = (f'[[experiment]]\nname = "extra"\nfile = "{rig / "T1.csv"}"\ntank_volume = 5e-5\nchannels = ["pressure"]\n'
             'scales = { pressure = 2e3 }\ninitial = { INITIAL = 101325.0 }\n')
    setup = load(_bench_config(rig, tmp_path, extra.replace("INITIAL", "pressure")))
    assert [e.name for e in setup.experiments][-1] == "extra" and isinstance(setup.model, pj.Rig)
    with pytest.raises(PamjaxInputError, match=r"\[\[experiment\]\] #1 initial"):
        load(_bench_config(rig, tmp_path, extra.replace("INITIAL", "presure")))


def test_a_rig_experiment_named_by_a_number_gets_a_path_the_fit_reads(rig, tmp_path):
    # [rig] free = ["supply_pressure"] of an [[experiment]] named "1" was runs[1].supply_pressure: an array index.
    from pamjax._cli.fit import load

    cfg = tmp_path / "rig.toml"
    cfg.write_text('[model]\npreset = "mas10_system"\noptions = { valve = "pwm", friction = "karnopp" }\n'
                   '[fit]\nfree = ["valve.inflate.discharge_coefficient"]\n[rig]\nfree = ["supply_pressure"]\n'
                   f'[[experiment]]\nname = "1"\nfile = "{rig / "T1.csv"}"\ntank_volume = 5e-5\n'
                   'channels = ["pressure"]\nscales = { pressure = 2e3 }\nsupply_pressure = 6.3e5\n')
    setup = load(cfg)
    assert setup.free == ["plant.valve.inflate.discharge_coefficient", "runs['1'].supply_pressure"]
    assert pj.ParameterSpace(setup.model, setup.free).initial_values()[1] == 6.3e5


def test_a_nuisance_report_of_something_else_than_a_fit_result_is_named():
    # nuisance_report(None) was a raw AttributeError
    with pytest.raises(pj.PamjaxInputError, match=r"nuisance_report: result must be a fit result .* got NoneType"):
        pj.nuisance_report(None)


@pytest.mark.parametrize("build, field", [
    (lambda: pj.StartState(pressure=float("nan")), "StartState.pressure"),
    (lambda: pj.StartState(pressure=-2e5), "StartState.pressure"),
    (lambda: pj.StartState(position=float("inf")), "StartState.position"),
    (lambda: pj.RunConditions(supply_pressure=float("nan")), "RunConditions.supply_pressure"),
    (lambda: pj.RunConditions(supply_pressure=5.5), "RunConditions.supply_pressure"),  # bar typed
])
def test_run_conditions_refuse_a_non_finite_or_non_absolute_pressure_by_name(build, field):
    # NaN reached the solve, which failed naming neither field; -2e5 Pa abs was simulated
    with pytest.raises(PamjaxInputError, match=field):
        build()


def test_gauge_pressures_of_a_rig_file_are_relative_to_its_plants_air(tmp_path):
    base = presets.mas10_system("pwm")
    plant = pj.MuscleSystem(base.valve, base.muscle, air=pj.Air(atmospheric_pressure=83400.0))  # a bench at 1,600 m
    rig = pj.Rig(plant, runs={"E1": pj.RunConditions(6.0e5, pj.StartState(pressure=2e5))})
    path = pj.save_model(tmp_path / "rig.json", rig)
    d = json.loads(path.read_text())
    d["parameters"]["runs.E1.supply_pressure"].update(value=5.5, unit="barg")
    d["parameters"]["runs.E1.start.pressure"].update(value=1.0, unit="barg")
    path.write_text(json.dumps(d))
    back = pj.load_model(path)  # they were read against the standard atmosphere: 651325 and 201325
    np.testing.assert_allclose(float(back.runs["E1"].supply_pressure), 5.5e5 + 83400.0, rtol=1e-12)
    np.testing.assert_allclose(float(back.runs["E1"].start.pressure), 1e5 + 83400.0, rtol=1e-12)


def test_a_rig_file_with_several_values_in_a_sensor_or_run_field_is_refused(tmp_path):
    rig = pj.Rig(presets.mas10_tank_system("pwm"), runs={"E1": pj.RunConditions(6.5e5)})
    path = pj.save_model(tmp_path / "rig.json", rig)
    for key in ("sensors.rig.pressure_gain", "runs.E1.supply_pressure"):
        d = json.loads(path.read_text())
        d["parameters"][key]["value"] = [d["parameters"][key]["value"]] * 2
        edited = tmp_path / "edited.json"
        edited.write_text(json.dumps(d))
        with pytest.raises(PamjaxInputError, match=rf"{re.escape(key)}' has shape \(2,\) where the model takes one"):
            pj.load_model(edited)
