"""Bench directories (`pamjax.bench.load_bench`) and `fits/joint.py --data DIR`: a small synthetic bench in the shared
layout (meta.json + npz), made by pamjax's exact stick-slip model from known parameters, fitted from the presets."""

import importlib.util
import json
import pathlib

import numpy as np
import pytest

import pamjax as pj
from pamjax import PamjaxInputError, presets

ROOT = pathlib.Path(__file__).resolve().parents[1]
FACTORS = {"Cv12": 1.08, "b12": 0.93, "Cv23": 0.94, "b23": 1.05, "v1": 0.8, "Fc": 1.15, "Cf": 0.9}
KEYS = list(FACTORS)
NOISE = {"p_std_Pa": 2000.0, "x_std_m": 1e-4}


def _truth():
    model = presets.mas10_system(valve="pwm", friction="karnopp")
    space = pj.ParameterSpace(model, [pj.bench.BENCH_PARAMETERS[k][0] for k in KEYS])
    values = np.asarray(space.initial_values()) * np.array([FACTORS[k] for k in KEYS])
    return space.with_values(values), dict(zip(KEYS, values.tolist()))


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """E1 (tank charge, duty 0.5), E2 (discharge, 0.25), E3 (triangle 0.5 Hz): short runs at 500 Hz, seeded."""
    folder = tmp_path_factory.mktemp("bench")
    truth, params = _truth()
    experiments = {
        "E1": dict(kind="tank_charge", V_tank=5e-5, u=0.5, t_end=0.4, p0="p_atm"),
        "E2": dict(kind="tank_discharge", V_tank=5e-5, u=0.25, t_end=0.4, p0="p_s"),
        "E3": dict(kind="muscle_triangle", f_tri=0.5, lo=0.05, hi=0.95, t_end=2.0),
        "E5": dict(kind="muscle_PI", kp=25.0),  # listed, not fitted
    }
    rng = np.random.default_rng(3)
    for name, e in list(experiments.items())[:3]:
        ts = np.arange(0.0, e["t_end"] + 1e-9, 2e-3)
        if e["kind"].startswith("tank"):
            system = pj.TankFromModel(5e-5)(truth)
            signal = pj.Constant(e["u"])
            y0 = system.initial_state(101325.0 if e["p0"] == "p_atm" else 6.5e5)
        else:
            system, signal, y0 = truth, pj.Triangle(e["lo"], e["hi"], e["f_tri"]), None
        traj = pj.simulate(system, signal, ts, y0=y0, substeps=32)
        p = np.asarray(traj.pressure) + NOISE["p_std_Pa"] * rng.standard_normal(ts.size)
        x = np.zeros_like(ts) if traj.position is None else np.asarray(traj.position) + NOISE[
            "x_std_m"] * rng.standard_normal(ts.size)
        u = np.asarray(traj.command)
        np.savez(folder / f"{name}.npz", t=ts, u=u, p=p, x=x)
    meta = dict(params=params, fitted_keys=KEYS, experiments=experiments, noise=NOISE)
    (folder / "meta.json").write_text(json.dumps(meta))
    return folder, params


def test_load_bench(bench):
    folder, _ = bench
    model = presets.mas10_system(valve="pwm", friction="karnopp")
    b = pj.bench.load_bench(folder, model)
    assert [e.name for e in b.experiments] == ["E1", "E2", "E3"] and "E5" in b.skipped
    assert b.noise == {"pressure": 2000.0, "position": 1e-4}
    e2 = b.experiments[1]  # p_s: the run's supply pressure, here the model valve's
    assert e2.start_at_supply and float(e2.start_for(e2.system_for(model), model).pressure) == pytest.approx(6.5e5)
    assert b.experiments[2].channels == ("pressure", "position")
    half = pj.bench.load_bench(folder, model, rate=250.0)
    assert len(half.experiments[0].times) == (len(b.experiments[0].times) + 1) // 2
    with pytest.raises(PamjaxInputError, match="not bench parameters.*valid"):
        pj.bench.load_bench(folder, model, fitted_keys=["Cv12", "nonsense"])
    with pytest.raises(PamjaxInputError, match="no meta.json"):
        pj.bench.load_bench(ROOT, model)
    # runs: some of the bench's experiments by name (a pilot's tests before a design), the others skipped and said
    pilot = pj.bench.load_bench(folder, model, runs=["E3", "E1"])
    assert [e.name for e in pilot.experiments] == ["E1", "E3"] and "not in runs" in pilot.skipped["E2"]
    assert pilot.free == b.free and pilot.noise == b.noise
    np.testing.assert_array_equal(pilot.experiments[1].times, b.experiments[2].times)
    for runs, match in ((["E9"], r"runs \['E9'\] are not experiments of its meta.json; it has \['E1', 'E2', 'E3', "
                                 r"'E5'\]"),
                        (["E5"], r"runs \['E5'\] are of kinds \['muscle_PI'\], not among kinds"),
                        ("E3", "runs must be a non-empty list of experiment names"), ([], "non-empty list")):
        with pytest.raises(PamjaxInputError, match=match):
            pj.bench.load_bench(folder, model, runs=runs)


def test_joint_script_fits_a_bench_directory_from_the_presets(bench, tmp_path):
    folder, params = bench
    spec = importlib.util.spec_from_file_location("joint", ROOT / "fits" / "joint.py")
    joint = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(joint)
    out = tmp_path / "out"
    # --no-cache: the script would turn the persistent cache on in PAMJAX_CACHE_DIR (the session's, when the tests
    # have one: tests/conftest.py, whose cache this run still uses), else in the user's cache directory
    joint.main(["--data", str(folder), "--out", str(out), "--quiet", "--max-steps", "60", "--no-cache",
                "--profile", "Fc"])
    result = json.loads((out / "joint.json").read_text())
    assert (out / "joint.png").exists()
    assert result["status"] == "converged", result["message"]
    # model.json: the fitted plant, as pamjax fit writes it (a [model] file of pamjax design or simulate)
    fitted = pj.load_model(out / "model.json")
    assert float(fitted.friction.coulomb_force) == pytest.approx(result["params"]["Fc"], rel=1e-12)
    provenance = json.loads((out / "model.json").read_text())["provenance"]
    assert provenance["status"] == "converged"
    assert provenance["written_by"].endswith("--max-steps 60 --no-cache --profile Fc")  # its flags, not --data alone
    # --profile Fc: its likelihood-ratio interval by the bench's name, around the fitted value, covering the truth
    # (a well-moving payload: the interval is about the linearised one), and profile.json / profile.png beside
    prof = result["profile"]
    assert set(prof["params"]) == {"Fc"} and prof["params"]["Fc"]["verdict"] == "identifiable"
    lo, hi = prof["params"]["Fc"]["interval"]
    assert lo < result["params"]["Fc"] < hi and lo < params["Fc"] < hi
    lin = prof["params"]["Fc"]["linearised"]
    assert 0.5 < (hi - lo) / (lin[1] - lin[0]) < 2.0
    assert not prof["warnings"] and prof["refits"] == []
    assert json.loads((out / "profile.json").read_text())["labels"] == ["friction.coulomb_force"]
    assert (out / "profile.png").stat().st_size > 10_000
    assert set(result["params"]) == set(KEYS) and set(result["std_err"]) == set(KEYS)
    for k in KEYS:  # recovered within 4 standard errors of the truth
        assert abs(result["params"][k] - params[k]) < 4 * result["std_err"][k], (k, result["params"][k], params[k])
    assert set(result["rmse"]) == {"E1", "E2", "E3"} and set(result["rmse"]["E3"]) == {"p", "x"}
    for name, chans in result["rmse_over_noise"].items():
        assert all(0.9 < r < 1.1 for r in chans.values()), (name, chans)
    assert not result["mismatch"]
    # the staged start (pamjax.staged_start): the valve on the tank tests alone, then the rest on the muscle run
    stages = {st["stage"]: st for st in result["stages"]}
    assert set(stages) == {"1", "2"}
    assert stages["1"]["experiments"] == ["E1", "E2"] and all(p.startswith("valve.") for p in stages["1"]["free"])
    assert len(stages["1"]["free"]) == 4 and stages["2"]["experiments"] == ["E3"]
    assert sorted(stages["2"]["free"]) == sorted(pj.bench.BENCH_PARAMETERS[k][0] for k in ("v1", "Fc", "Cf"))
    assert stages["1"]["status"] == "converged"  # four valve parameters on two tank tests: well posed
    assert result["stage2_start"] is None  # no force-law coefficient free: nothing for the force balance to move
    with pytest.raises(SystemExit, match="--overwrite"):
        joint.main(["--data", str(folder), "--out", str(out), "--quiet"])
    # --overwrite replaces the earlier results whole, as pamjax fit does (was: the earlier --profile's files kept,
    # reading as this run's)
    joint.main(["--data", str(folder), "--out", str(out), "--quiet", "--max-steps", "2", "--no-cache", "--joint-only",
                "--overwrite"])
    assert (out / "joint.json").is_file() and "profile" not in json.loads((out / "joint.json").read_text())
    assert not (out / "profile.json").exists() and not (out / "profile.png").exists()


def test_joint_script_names_a_parameter_it_cannot_profile_before_any_fit(bench, tmp_path, capsys):
    folder, _ = bench
    spec = importlib.util.spec_from_file_location("joint", ROOT / "fits" / "joint.py")
    joint = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(joint)
    out = tmp_path / "out"
    for bad in ("k2", "Fc,nonsense", ","):  # k2 is held (not fitted); an unknown name; nothing named
        with pytest.raises(SystemExit) as exit_:
            joint.main(["--data", str(folder), "--out", str(out), "--quiet", "--no-cache", "--profile", bad])
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert "--profile" in err and ("is not a fitted parameter" in err or "names no parameter" in err), err
        assert "Fc" in err  # what it can profile: the bench keys fitted
        assert not out.exists()  # named before any fit: nothing written, no folder left behind
    for count in ("0", "-2"):  # was: the single fit, silently
        with pytest.raises(SystemExit) as exit_:
            joint.main(["--data", str(folder), "--out", str(out), "--quiet", "--no-cache", "--multistart", count])
        assert exit_.value.code == 2 and "--multistart must be >= 1" in capsys.readouterr().err
        assert not out.exists()
    for bad, named in (("E9", "runs ['E9'] are not experiments of its meta.json"), (",", "non-empty list")):
        with pytest.raises(SystemExit) as exit_:  # --runs: meta.json's experiments only, named before any fit
            joint.main(["--data", str(folder), "--out", str(out), "--quiet", "--no-cache", "--runs", bad])
        assert exit_.value.code == 2 and named in capsys.readouterr().err and not out.exists()


def test_fitted_labels_takes_bench_keys_labels_and_indexed_labels():
    rig = ["plant.valve.inflate.discharge_coefficient", "a0", "a1", "plant.friction.coulomb_force",
           "sensors[rig].delay", "runs[E4].start.pressure"]
    pick = pj.bench.fitted_labels
    assert pick("Fc, a1,sensors[rig].delay", rig) == ["plant.friction.coulomb_force", "a1", "sensors[rig].delay"]
    assert pick(["Cv12", "plant.valve.inflate.discharge_coefficient"], rig) == [rig[0]]  # one label, once
    assert pick("all", rig) == rig
    plain = ["valve.coefficients[1,0]", "valve.coefficients[1,1]", "friction.coulomb_force"]
    assert pick("valve.coefficients[1,1],Fc", plain) == [plain[1], plain[2]]  # the index's comma is no separator
    with pytest.raises(PamjaxInputError, match=r"--profile: 'k0' is not a fitted parameter; give bench keys "
                                               r"\(Cv12, a0, a1, Fc\), the fit's labels"):
        pick("k0", rig, "--profile")
    with pytest.raises(PamjaxInputError, match="names no parameter"):
        pick(" , ", rig)


def test_staged_start_needs_experiments_that_see_part_of_the_model(bench):
    # Stages come from the experiments' structure: where every experiment's system has every free parameter (here
    # the muscle run alone), or an entry cannot be placed, there is nothing to stage and the model comes back as is.
    folder, _ = bench
    model = presets.mas10_system(valve="pwm", friction="karnopp")
    b = pj.bench.load_bench(folder, model)
    run = [e for e in b.experiments if e.name == "E3"]
    staged = pj.staged_start(model, run, b.free)
    assert staged.stages == [] and staged.model is model and staged.summary() == []
    tanks = [e for e in b.experiments if e.name != "E3"]  # tank tests only see the valve: nothing left for stage 2
    valve = [p for p in b.free if p.startswith("valve.")]
    assert pj.staged_start(model, tanks, valve).stages == []
    assert pj.staged_start(model, b.experiments, [("not", "a", "path")]).stages == []


def test_staged_start_compiles_the_joint_problem_beside_its_stages(bench):
    # Stage 2's and the joint problem's programs are compiled in a second thread while stage 1 fits: the joint fit
    # after `staged_start` then compiles nothing, and the start is bitwise the one of a staged start without that
    # thread.
    # (C_f held: a problem structure no other test of this module compiles, so the programs are new here.)
    folder, _ = bench
    model = presets.mas10_system(valve="pwm", friction="karnopp")
    b = pj.bench.load_bench(folder, model)
    free = [p for p in b.free if p != pj.bench.BENCH_PARAMETERS["Cf"][0]]
    staged = pj.staged_start(model, b.experiments, free, max_steps=60, progress=False)
    assert staged.precompile_s > 0.0 and 0.0 <= staged.waited_s <= staged.precompile_s
    assert staged.compile_s >= sum(res.compile_s for *_, res in staged.stages)
    assert any("second thread" in line for line in staged.summary())
    with pj.runtime.CompileStats() as stats:
        res = pj.fit(staged.model, b.experiments, free, max_steps=60, progress=False)
    assert res.status == "converged", res.message
    assert stats.count["compile"] == 0, stats.summary()
    plain = pj.staged_start(model, b.experiments, free, max_steps=60, progress=False, background_compile=False)
    assert plain.precompile_s == 0.0 and plain.waited_s == 0.0
    np.testing.assert_array_equal(pj.ParameterSpace(plain.model, free).initial_values(),
                                  pj.ParameterSpace(staged.model, free).initial_values())


def test_pamjax_fit_with_a_bench_table_starts_stage_by_stage(bench, tmp_path, capsys):
    # `pamjax fit CONFIG` with [bench]: the same staged start and joint fit as fits/joint.py (the same compiled
    # programs, reused in this process), bench.json in the bench's names; `staged = false` is accepted, a non-boolean
    # refused naming the key.
    from pamjax._cli.main import main

    folder, params = bench
    cfg = tmp_path / "bench.toml"
    def body(staged):
        return ('[model]\npreset = "mas10_system"\noptions = { valve = "pwm", friction = "karnopp" }\n'
                f'[bench]\ndir = "{folder}"\n{staged}[fit]\nmax_steps = 60\n')

    cfg.write_text(body(""))
    assert main(["fit", str(cfg), "--out", str(tmp_path / "out"), "--quiet", "--no-plot"]) == 0
    out = capsys.readouterr().out
    assert "stage 1: 4 parameters on E1, E2" in out and "stage 2: 3 parameters on E3" in out
    result = json.loads((tmp_path / "out" / "bench.json").read_text())
    assert result["status"] == "converged" and set(result["params"]) == set(KEYS)
    assert set(result["rmse"]) == {"E1", "E2", "E3"} and "E5" in result["skipped"]  # what was fitted, what not
    for k in KEYS:
        assert abs(result["params"][k] - params[k]) < 4 * result["std_err"][k], k
    cfg.write_text(body("staged = 1\n"))
    assert main(["fit", str(cfg), "--out", str(tmp_path / "bad"), "--quiet", "--no-plot"]) == 2
    assert "[bench] staged" in capsys.readouterr().err

    # stopped at max_steps in its stages and its joint fit, then resumed with the budget raised as the report advises:
    # the joint fit goes on from the staged start it began at (kept beside the checkpoint), not from one computed
    # again with the larger budget (was: refused, "the start model differs")
    short = tmp_path / "short"
    cfg.write_text(body("").replace("max_steps = 60", "max_steps = 2"))
    assert main(["fit", str(cfg), "--out", str(short), "--quiet", "--no-plot"]) == 0
    out = capsys.readouterr().out
    assert "stage 2: 3 parameters on E3: max_steps" in out and "raise [fit] max_steps and continue" in out
    kept = np.load(short / "staged_start.npz")["values"]
    cfg.write_text(body(""))
    assert main(["fit", str(cfg), "--out", str(short), "--quiet", "--no-plot", "--resume"]) == 0
    out = capsys.readouterr().out
    assert "the staged start of the fit resumed (staged_start.npz):" in out and "\n  stage 2: 3 parameters" in out
    resumed = json.loads((short / "fit.json").read_text())
    assert resumed["status"] == "converged" and np.array_equal(np.load(short / "staged_start.npz")["values"], kept)
    # a staged start left without a checkpoint (stopped before the joint fit's first iteration, where the command says
    # to run it again as it was) is replaced, not refused
    again = tmp_path / "again"
    again.mkdir()
    (again / "staged_start.npz").write_bytes((short / "staged_start.npz").read_bytes())
    cfg.write_text(body("").replace("max_steps = 60", "max_steps = 2"))
    assert main(["fit", str(cfg), "--out", str(again), "--quiet", "--no-plot"]) == 0
    capsys.readouterr()
    # another problem (fewer runs): the kept start is refused, naming what differs
    other = body("").replace(f'dir = "{folder}"', f'dir = "{folder}"\nruns = ["E1", "E3"]')
    cfg.write_text(other)
    assert main(["fit", str(cfg), "--out", str(short), "--quiet", "--no-plot", "--resume"]) == 2
    assert "holds the staged start of a different fit" in capsys.readouterr().err


def test_noise_levels_left_out_of_meta_are_estimated_near_the_sensors_and_said(tmp_path):
    # The bundled bench's sensors have 2 kPa and 0.1 mm of white noise (its meta.json); without them the loader
    # estimates them from the recordings. From first differences a fast pressure's slope counted as noise (5.8 kPa,
    # 2.9x); second differences leave what the switching valve's kinks add (+13 % here).
    import shutil

    from pamjax.gallery import bench_folder

    folder = tmp_path / "bench"
    shutil.copytree(bench_folder(), folder)
    meta = json.loads((folder / "meta.json").read_text())
    sensors = meta.pop("noise")
    (folder / "meta.json").write_text(json.dumps(meta))
    bench = pj.bench.load_bench(folder, presets.mas10_system(valve="pwm", friction="karnopp"))
    assert bench.noise["pressure"] == pytest.approx(sensors["p_std_Pa"], rel=0.15)
    assert bench.noise["position"] == pytest.approx(sensors["x_std_m"], rel=0.05)
    said = [n for n in bench.notes if "noise estimated from the recordings" in n]
    assert len(said) == 2 and "meta.json 'noise' p_std_Pa" in said[0], bench.notes
    given = pj.bench.load_bench(bench_folder(), presets.mas10_system(valve="pwm", friction="karnopp"))
    assert given.noise == {"pressure": sensors["p_std_Pa"], "position": sensors["x_std_m"]}
    assert not any("noise estimated" in n for n in given.notes)


# --- CSV benches written by hand (no simulation: load_bench solves nothing) ----------------------------------------
def _csv_bench(folder, runs, **meta):
    """A bench folder of CSV files: `runs` = {name: (meta.json entry, header, columns)}; meta.json's other keys from
    `meta` (noise given, one fitted key)."""
    folder.mkdir(parents=True, exist_ok=True)
    for name, (entry, header, columns) in runs.items():
        lines = [header] + [",".join(f"{v:.6g}" for v in row) for row in np.column_stack(columns)]
        (folder / f"{name}.csv").write_text("\n".join(lines) + "\n")
    meta = {"experiments": {n: e for n, (e, _, _) in runs.items()}, "noise": NOISE, "fitted_keys": ["Cv12"], **meta}
    (folder / "meta.json").write_text(json.dumps(meta))
    return folder


T_RUN = np.arange(500) * 1e-3  # s: 0.5 s at 1 kHz
RISING = 20.0 + 20.0 * T_RUN  # mm: a payload moving up at 20 mm/s
MIDWAY = dict(kind="muscle_run", init="unknown: logged mid-way")
TRIANGLE = dict(kind="muscle_triangle", lo=0.05, hi=0.95, f_tri=0.5)


def _plant():
    return presets.mas10_system(valve="pwm", friction="karnopp")


def test_a_run_logged_mid_way_without_pressure_gets_its_start_from_position_and_model(tmp_path):
    # A run logged mid-way that records position but no pressure (was: nuisance=True crashed reading its pressure
    # for the start estimate): position and velocity from its first samples, the start pressure where the model rests
    # at that position, all three fitted, and said.
    folder = _csv_bench(tmp_path / "b", {"M": (MIDWAY, "t [s],duty [-],position [mm]",
                                              [T_RUN, np.full(500, 0.6), RISING])})
    bench = pj.bench.load_bench(folder, _plant(), nuisance=True)
    assert bench.experiments[0].channels == ("position",)
    assert {"runs[M].start.pressure", "runs[M].start.position", "runs[M].start.velocity"} <= set(bench.free)
    start = bench.model.runs["M"].start
    assert float(start.position) == pytest.approx(0.0199, abs=2e-4) and float(start.velocity) == pytest.approx(0.02)
    p_atm = float(_plant().air.atmospheric_pressure)
    assert p_atm < float(start.pressure) < p_atm + 1e6
    rest = _plant().initial_state(pressure=float(start.pressure))  # the model rests there at that pressure
    assert float(rest.position) == pytest.approx(float(start.position), abs=1e-5)
    assert any("M: start state fitted" in n and "not recorded" in n for n in bench.notes), bench.notes


def test_a_mid_way_starts_estimate_reads_the_data_through_the_given_calibration(tmp_path):
    # The start estimate subtracted the rest offset only: a calibrated pressure gain (1.05) left the start pressure
    # 5 % of its gauge value off (26 kPa at 520 kPa gauge), a calibrated position offset (2 mm) all of it. Both are
    # now read back through the rig's sensors, as the fit's model reads the plant.
    measured = np.full(500, 6.2)  # barg
    folder = _csv_bench(tmp_path / "b", {"M": (MIDWAY, "t [s],duty [-],pressure [barg],position [mm]",
                                              [T_RUN, np.full(500, 0.6), measured, RISING])})
    bench = pj.bench.load_bench(folder, _plant(), nuisance=["start"], pressure_gain=1.05, position_offset=0.002)
    start = bench.model.runs["M"].start
    p_atm = float(_plant().air.atmospheric_pressure)
    assert float(start.pressure) == pytest.approx(p_atm + 6.2e5 / 1.05, rel=1e-9)
    assert float(start.position) == pytest.approx(0.0199 - 0.002, abs=2e-4)


def test_a_triangle_without_duty_column_refused_mid_way_and_said_at_rest(tmp_path):
    # Logged mid-way, meta.json's triangle cannot drive a run without its recorded duty (its phase is unknown; was:
    # driven from phase 0, silently). At rest, it drives the run, and the notes say the command came from meta.json.
    columns = [T_RUN, np.full(500, 3.0), RISING]
    header = "t [s],pressure [barg],position [mm]"
    midway = _csv_bench(tmp_path / "mid", {"M": ({**TRIANGLE, "init": "unknown"}, header, columns)})
    with pytest.raises(PamjaxInputError, match=r"'M' was logged mid-way .*/M\.csv has no duty column .*phase .*"
                                               "unknown.*record the commanded duty"):
        pj.bench.load_bench(midway, _plant())
    at_rest = [T_RUN, np.zeros(500), RISING]  # at rest: the atmosphere (3 bar gauge is a run logged mid-way)
    rest = pj.bench.load_bench(_csv_bench(tmp_path / "rest", {"M": (TRIANGLE, header, at_rest)}), _plant())
    assert isinstance(rest.experiments[0].signal, pj.Triangle)
    assert any("M: no recorded duty column; driven by meta.json's triangle" in n for n in rest.notes), rest.notes


@pytest.mark.parametrize("duty, match", [
    (np.where(np.arange(500) == 3, 1.5, 0.6), r"M\.csv, line 6: the duty column 'duty' of experiment 'M' reads 1\.5 "
                                              r"there, outside \[0, 1\] \(its range: \[0\.6, 1\.5\]\); a duty ratio"),
    (np.where(np.arange(500) == 7, -0.1, 0.6), r"M\.csv, line 10: .* reads -0\.1 there"),
    (np.full(500, 60.0), r"M\.csv, line 3: .* reads 60 .*looks like percent: write its header 'duty \[%\]'"),
])
def test_a_recorded_duty_out_of_range_is_named_by_file_column_and_line(tmp_path, duty, match):
    # Was: blamed meta.json, gave the range only, and called any value up to 100 (a single 1.5) percent.
    folder = _csv_bench(tmp_path / "b", {"M": (MIDWAY, "t [s],duty [-],position [mm]", [T_RUN, duty, RISING])})
    path = folder / "M.csv"
    path.write_text("# logger export\n" + path.read_text())  # a comment line: counted in the file's lines
    with pytest.raises(PamjaxInputError, match=match) as err:
        pj.bench.load_bench(folder, _plant())
    assert "meta.json" not in str(err.value) and ("percent" in str(err.value)) == (duty.max() > 1.5)


def test_bad_rows_of_a_bench_recording_are_named_by_file_and_line(tmp_path):
    # Was: "Recording 'M': ... row 3" (0-based, no file) and advice to pass mask_nan=True, which load_bench and a
    # pamjax fit config cannot.
    folder = _csv_bench(tmp_path / "b", {"M": (MIDWAY, "t [s],duty [-],position [mm]",
                                              [T_RUN, np.full(500, 0.6), RISING])})
    path = folder / "M.csv"
    good = path.read_text().splitlines()
    for edit, match in (
            (lambda L: L[:4] + ["0.003,0.6,nan"] + L[5:], r"M\.csv, line 5: column 'position' \(channel 'position'\) "
                                                         r"of experiment 'M' is NaN/inf .*fix or delete that line"),
            (lambda L: L[:4] + [L[3]] + L[5:], r"M\.csv, line 5: t = 0\.002 s is not after the sample before it "
                                               r"\(line 4: .*strictly increasing"),
            (lambda L: L[:1], r"M\.csv: 0 data rows")):
        path.write_text("\n".join(edit(good)) + "\n")
        with pytest.raises(PamjaxInputError, match=match) as err:
            pj.bench.load_bench(folder, _plant())
        assert "mask_nan" not in str(err.value)


def test_meta_json_units_apply_to_csv_columns_without_header_units(tmp_path):
    # A CSV headed 't,u,p,x' with meta.json "units" {"p": "barg", "x": "mm"} (was: the units ignored for CSV files,
    # and the pressure refused as looking like bar); a header unit that contradicts meta.json's is refused naming both.
    run = {"M": (MIDWAY, "t,u,p,x", [T_RUN, np.full(500, 0.6), 3.0 + T_RUN, RISING])}
    folder = _csv_bench(tmp_path / "b", run, units={"p": "barg", "x": "mm"})
    data = pj.bench.load_bench(folder, _plant()).experiments[0].data
    np.testing.assert_allclose(data["pressure"], 101325.0 + 1e5 * (3.0 + T_RUN))
    np.testing.assert_allclose(data["position"], RISING * 1e-3)
    both = _csv_bench(tmp_path / "both", {"M": (MIDWAY, "t,u,p [bar abs],x", run["M"][2])},
                      units={"p": "barg", "x": "mm"})
    with pytest.raises(PamjaxInputError, match=r"M\.csv: column 'p' is in 'bar abs' by the file, but meta\.json "
                                               r"'units' .*says 'p' is in 'barg'"):
        pj.bench.load_bench(both, _plant())


def test_a_meta_json_with_a_byte_order_mark_is_read(tmp_path):
    """Notepad's "UTF-8 with BOM": meta.json was refused ("Unexpected UTF-8 BOM"), the CSV beside it read."""
    run = {"M": (MIDWAY, "t,u,p,x", [T_RUN, np.full(500, 0.6), 3.0 + T_RUN, RISING])}
    folder = _csv_bench(tmp_path / "b", run, units={"p": "barg", "x": "mm"})
    meta = folder / "meta.json"
    meta.write_bytes(b"\xef\xbb\xbf" + meta.read_bytes())
    data = pj.bench.load_bench(folder, _plant()).experiments[0].data
    np.testing.assert_allclose(data["position"], RISING * 1e-3)


def test_meta_json_atmosphere_is_the_models(tmp_path):
    # atmosphere_Pa converts the gauge readings and is the model's atmosphere too (was: the readings referred to
    # 95 kPa, the model's exhaust, tank start and rest to 101325 Pa); said in the notes.
    t = np.arange(200) * 1e-3
    tank = (dict(kind="tank_charge", V_tank=5e-5, u=0.5, p0="p_atm"), "t [s],duty [-],pressure [barg]",
            [t, np.full(200, 0.5), 2.0 * t])
    folder = _csv_bench(tmp_path / "b", {"T": tank}, atmosphere_Pa=95000.0)
    bench = pj.bench.load_bench(folder, _plant())
    assert float(bench.model.air.atmospheric_pressure) == 95000.0
    e = bench.experiments[0]
    assert float(e.initial["pressure"]) == 95000.0 and e.data["pressure"][0] == pytest.approx(95000.0)
    assert any("atmospheric pressure set to 95000 Pa" in n for n in bench.notes), bench.notes
    rig = pj.bench.load_bench(folder, _plant(), nuisance=True)  # the Rig's plant too
    assert float(rig.model.plant.air.atmospheric_pressure) == 95000.0


# --- mistakes in a bench folder named before any fit, and what the loader leaves out said ---------------------------
T_TANK = np.arange(200) * 1e-3  # s
TANK = (dict(kind="tank_charge", V_tank=5e-5, u=0.5, p0="p_atm"), "t [s],duty [-],pressure [barg]",
        [T_TANK, np.full(200, 0.5), 2.0 * T_TANK])
RUN_HEADER = "t [s],duty [-],{} [barg],position [mm]"
RUN_COLUMNS = [T_RUN, np.full(500, 0.6), 3.0 + T_RUN, RISING]


def test_an_unknown_kind_is_refused_naming_the_run_meta_json_and_the_kinds(tmp_path):
    # A typo in a run's kind (was: the run silently left out, its reason only in Bench.skipped).
    folder = _csv_bench(tmp_path / "b", {"T": TANK, "M": ({**MIDWAY, "kind": "muscle_trianlge"},
                                                          RUN_HEADER.format("pressure"), RUN_COLUMNS)})
    with pytest.raises(PamjaxInputError, match=r"b/meta\.json: experiment 'M' has kind 'muscle_trianlge', which pamjax "
                                               r"does not know \(did you mean 'muscle_triangle'\?\); write one of "
                                               r"\['tank_charge', 'tank_discharge', 'muscle_triangle', 'muscle_run'\] "
                                               r"\(fitted\) or \['muscle_PI'\] \(known, not fitted\)"):
        pj.bench.load_bench(folder, _plant())
    known = _csv_bench(tmp_path / "k", {"T": TANK, "M": ({"kind": "muscle_PI"}, RUN_HEADER.format("pressure"),
                                                         RUN_COLUMNS)})
    assert set(pj.bench.load_bench(known, _plant()).skipped) == {"M"}  # known, not fitted: left out, as before


@pytest.mark.parametrize("where, key, close", [
    ("run", "payload_kgs", "payload_kg"), ("run", "Payload_kg", "payload_kg"),
    ("top", "atmosphere_pa", "atmosphere_Pa"), ("noise", "p_std", "p_std_Pa")])
def test_a_misspelt_meta_json_key_is_refused_naming_the_file_and_the_closest_key(tmp_path, where, key, close):
    # Was: ignored, the run fitted with the model's payload or the gauge readings converted with 101325 Pa.
    run = ({**MIDWAY, **({key: 30.0} if where == "run" else {})}, RUN_HEADER.format("pressure"), RUN_COLUMNS)
    extra = {"top": {key: 95000.0}, "noise": {"noise": {**NOISE, key: 2000.0}}}.get(where, {})
    folder = _csv_bench(tmp_path / "b", {"T": TANK, "M": run}, **extra)
    with pytest.raises(PamjaxInputError, match=rf"b/meta\.json.* has key '{key}', which pamjax does not know \(did you "
                                               rf"mean '{close}'\?\)"):
        pj.bench.load_bench(folder, _plant())


def test_the_keys_of_every_shared_bench_meta_json_are_known():
    # The truth listings (params, nuisance) and a bench's own description are allowed, unread.
    from pamjax._bench.files import read_meta

    shared = [f.parent for root in (ROOT / "shared", ROOT.parent / "shared") for f in root.glob("data/**/meta.json")]
    for folder in [ROOT / "pamjax/data/hybrid-reference-bench", *shared]:
        read_meta(folder)


def test_a_pressure_column_not_read_as_pressure_is_named_or_said(tmp_path):
    # `presure [barg]` in a muscle run (was: left out of the fit in silence; a tank run said "no pressure column"
    # without naming it); `pressure (bar(g))` reads as the pressure; a run that has no pressure at all is said.
    typo = _csv_bench(tmp_path / "typo", {"M": (MIDWAY, RUN_HEADER.format("presure"), RUN_COLUMNS)})
    with pytest.raises(PamjaxInputError, match=r"M\.csv: column 'presure' is in a pressure unit \('barg'\) but is not "
                                               r"a channel pamjax reads, and experiment 'M' has no pressure column: "
                                               r"if it is the pressure, head it 'pressure \[barg\]'"):
        pj.bench.load_bench(typo, _plant())
    tank = _csv_bench(tmp_path / "tank", {"T": (TANK[0], "t [s],duty [-],presure [barg]", TANK[2])})
    with pytest.raises(PamjaxInputError, match=r"T\.csv: column 'presure' is in a pressure unit"):
        pj.bench.load_bench(tank, _plant())
    paren = _csv_bench(tmp_path / "paren", {"M": (MIDWAY, "t [s],duty [-],pressure (bar(g)),position [mm]",
                                                  RUN_COLUMNS)})
    bench = pj.bench.load_bench(paren, _plant())
    assert bench.experiments[0].channels == ("pressure", "position")
    np.testing.assert_allclose(bench.experiments[0].data["pressure"], 101325.0 + 1e5 * (3.0 + T_RUN))
    none = _csv_bench(tmp_path / "none", {"M": (MIDWAY, "t [s],duty [-],position [mm]", [T_RUN, RUN_COLUMNS[1],
                                                                                         RISING])})
    notes = pj.bench.load_bench(none, _plant()).notes
    assert any("M: no pressure column in M.csv: fitted on its position alone" in n for n in notes), notes


def test_columns_a_bench_does_not_fit_from_are_ignored_and_said(tmp_path):
    # docs/fitting.md: "other columns ignored" (was: a 'dp_filter [Pa]' refused as looking like kPa, an empty 'notes'
    # column as NaN at row 0, a text 'status' column as not a number, 'force [kgf]' as a unit pamjax does not know).
    plain = pj.bench.load_bench(_csv_bench(tmp_path / "plain", {"T": TANK}), _plant())
    header = TANK[1] + ",dp_filter [Pa],notes,status,force [kgf]"
    folder = _csv_bench(tmp_path / "b", {"T": (TANK[0], header, [*TANK[2], np.full(200, 850.0)])})
    path = folder / "T.csv"
    head, *rows = path.read_text().splitlines()
    path.write_text("\n".join([head] + [row + f",,{'OK' if k else 'FAULT'},8" for k, row in enumerate(rows)]) + "\n")
    bench = pj.bench.load_bench(folder, _plant())
    np.testing.assert_array_equal(bench.experiments[0].data["pressure"], plain.experiments[0].data["pressure"])
    said = [n for n in bench.notes if "ignored" in n]
    assert said == ["T: T.csv's 'dp_filter', 'notes', 'status', 'force' ignored (a bench run is fitted from its time, "
                    "duty, pressure and position)"], bench.notes
    rows[3] = rows[3].replace(rows[3].split(",")[2], "nan")  # the columns used keep every check
    path.write_text("\n".join([head] + [row + ",,OK,8" for row in rows]) + "\n")
    with pytest.raises(PamjaxInputError, match=r"T\.csv, line 5: column 'pressure' \(channel 'pressure'\) .* NaN/inf"):
        pj.bench.load_bench(folder, _plant())


def test_a_recording_with_an_upper_case_extension_is_found(tmp_path):
    # E1.CSV (was: "has no recording E1.npz, E1.csv or E1.mat (the folder holds E1.CSV)"); two spellings: refused.
    folder = _csv_bench(tmp_path / "b", {"T": TANK})
    (folder / "T.csv").rename(folder / "T.CSV")
    bench = pj.bench.load_bench(folder, _plant())
    np.testing.assert_allclose(bench.experiments[0].data["pressure"], 101325.0 + 2e5 * T_TANK)
    (folder / "T.csv").write_text((folder / "T.CSV").read_text())
    if len({p.name.lower() for p in folder.iterdir()}) < len(list(folder.iterdir())):  # a case-sensitive file system
        with pytest.raises(PamjaxInputError, match=r"'T' has 2 recordings \(T\.CSV, T\.csv\); keep one"):
            pj.bench.load_bench(folder, _plant())


def test_a_tank_volume_beyond_any_test_tank_is_refused_naming_meta_json(tmp_path):
    # V_tank = 50 (cm^3 written as m^3; was: accepted, and refused inside the fit naming neither meta.json nor V_tank,
    # after `pamjax fit` had made its output folder).
    folder = _csv_bench(tmp_path / "b", {"T": ({**TANK[0], "V_tank": 50.0}, TANK[1], TANK[2])})
    with pytest.raises(PamjaxInputError, match=r"b/meta\.json: tank test 'T' has V_tank = 50 m\^3, more than 0\.1 m\^3 "
                                               r"\(100 litres\).* looks like litres \(50 l = 0\.05 m\^3\) or cm\^3 "
                                               r"\(50 cm\^3 = 5e-05 m\^3\)"):
        pj.bench.load_bench(folder, _plant())


def test_mat_variables_that_are_no_channel_are_ignored_and_units_go_in_meta_json(tmp_path):
    # A 5-value `temp`, a scalar and a string beside t, u, p, x (was: "Recording 'T': channel 'temp' has shape (5,),
    # expected (200,)", the file not named); a channel cut short is named with its file; times in ms without a unit
    # are refused saying to give meta.json "units" (was: "write 't [ms]' in the header", which a MAT file has not).
    scipy_io = pytest.importorskip("scipy.io")
    folder = _csv_bench(tmp_path / "b", {"T": TANK}, units={"p": "barg"})
    (folder / "T.csv").unlink()
    t, u, p = TANK[2]
    scipy_io.savemat(folder / "T.mat", dict(t=t, u=u, p=p, temp=np.full(5, 20.0), fs=1000.0, rig="A"))
    bench = pj.bench.load_bench(folder, _plant())
    np.testing.assert_allclose(bench.experiments[0].data["pressure"], 101325.0 + 2e5 * t)
    assert any("T: T.mat's 'temp' ignored" in n for n in bench.notes), bench.notes
    scipy_io.savemat(folder / "T.mat", dict(t=t, u=u, p=p[:-1]))
    with pytest.raises(PamjaxInputError, match=r"T\.mat: 'p' \(channel 'pressure'\) has 199 values, the time 200"):
        pj.bench.load_bench(folder, _plant())
    scipy_io.savemat(folder / "T.mat", dict(t=t * 1e3, u=u, p=p))
    with pytest.raises(PamjaxInputError, match=r"T\.mat: 't' is sampled every 1 s .*give its unit, \{\"t\": \"ms\"\}, "
                                               r"in meta\.json's \"units\""):
        pj.bench.load_bench(folder, _plant())


def test_pamjax_fit_prints_the_runs_left_out_and_the_loaders_notes(tmp_path, monkeypatch, capsys):
    # `pamjax fit` with a [bench] (was: neither the skipped runs nor the notes printed, as fits/joint.py prints them);
    # the fit itself interrupted as it starts: nothing is solved.
    from pamjax._cli.main import main

    folder = _csv_bench(tmp_path / "b", {"T": (TANK[0], TANK[1] + ",valve_current [mA]", [*TANK[2], np.ones(200)]),
                                         "P": ({"kind": "muscle_PI"}, RUN_HEADER.format("pressure"), RUN_COLUMNS)})

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(pj, "fit", interrupted)
    cfg = tmp_path / "bench.toml"
    cfg.write_text(f'[model]\npreset = "mas10_system"\noptions = {{ valve = "pwm", friction = "karnopp" }}\n'
                   f'[bench]\ndir = "{folder}"\nstaged = false\n')
    assert main(["fit", str(cfg), "--out", str(tmp_path / "out"), "--quiet", "--no-plot"]) == 130
    out = capsys.readouterr().out
    assert f"bench {folder}: left out: P (kind 'muscle_PI' not fitted" in out, out
    assert "\n  T: T.csv's 'valve_current' ignored" in out, out


AT_REST = [T_RUN, np.zeros(500), 0.02 + np.zeros(500), -15.0 + 0.1 * np.sin(T_RUN * 400)]  # 2 kPa offset, still


def test_a_partial_list_of_a0_to_a4_or_a_name_for_a_list_is_refused(tmp_path):
    # a0…a4 are one array: fitted_keys ["Cv12", "a0"] freed all five and reported a0 alone; a string was read as its
    # characters ("C", "v", ...).
    folder = _csv_bench(tmp_path / "b", {"M": ({"kind": "muscle_run"}, RUN_HEADER.format("pressure"), AT_REST)})
    with pytest.raises(PamjaxInputError, match=r"fitted_keys name \['a0'\] of a0…a4.*one array.*give all five"):
        pj.bench.load_bench(folder, _plant(), fitted_keys=["Cv12", "a0"])
    with pytest.raises(PamjaxInputError, match=r"fitted_keys must be a list of bench parameter names .*'Cv12'"):
        pj.bench.load_bench(folder, _plant(), fitted_keys="Cv12")
    whole = pj.bench.load_bench(folder, _plant(), fitted_keys=("Cv12", "a0", "a1", "a2", "a3", "a4"))
    assert whole.free == ["valve.inflate.discharge_coefficient", "muscle.force_law.max_force_coefficients"]
    assert whole.fitted_keys == ["Cv12", "a0", "a1", "a2", "a3", "a4"]


def test_the_noise_estimate_is_taken_at_the_recorded_rate(tmp_path):
    # Decimating keeps recorded samples (each sample's noise as it was) but aliases the 50 Hz PWM ripple into the
    # second differences: at 100 Hz the pressure's estimate was 6-9x the sensor's on realistic1.
    import shutil

    from pamjax.gallery import bench_folder

    folder = tmp_path / "bench"
    shutil.copytree(bench_folder(), folder)
    meta = json.loads((folder / "meta.json").read_text())
    meta.pop("noise")
    (folder / "meta.json").write_text(json.dumps(meta))
    full = pj.bench.load_bench(folder, _plant())
    for rate in (200.0, 100.0):
        low = pj.bench.load_bench(folder, _plant(), rate=rate)
        assert low.noise == full.noise and len(low.experiments[0].times) < len(full.experiments[0].times)


def test_a_start_estimate_at_a_low_rate_takes_enough_samples(tmp_path):
    # At 25 Hz the first 20 ms held one sample, and the line through it raised numpy's LinAlgError.
    folder = _csv_bench(tmp_path / "b", {"M": (MIDWAY, "t [s],duty [-],position [mm]",
                                              [T_RUN, np.full(500, 0.6), RISING])})
    bench = pj.bench.load_bench(folder, _plant(), nuisance=True, rate=25.0)
    assert float(bench.model.runs["M"].start.velocity) == pytest.approx(0.02)
    assert any("M: start state fitted" in n and "first 80 ms of data" in n for n in bench.notes), bench.notes


def test_runs_named_by_numbers_are_quoted_in_their_paths_and_a_name_no_path_holds_is_refused(tmp_path):
    # Was: runs[1].supply_pressure, which the fit's own path parser refuses (an array index).
    runs = {"1": ({"kind": "muscle_run"}, RUN_HEADER.format("pressure"), AT_REST)}
    bench = pj.bench.load_bench(_csv_bench(tmp_path / "num", runs), _plant(), nuisance=True)
    assert "runs['1'].supply_pressure" in bench.free
    space = pj.ParameterSpace(bench.model, bench.free)
    assert "runs['1'].supply_pressure" in space.labels
    bad = _csv_bench(tmp_path / "bad", {"E]2": runs["1"]})
    with pytest.raises(PamjaxInputError, match=r"run 'E\]2' cannot be named in a parameter path .*rename the run"):
        pj.bench.load_bench(bad, _plant(), nuisance=True)


def test_a_muscle_run_logged_mid_way_without_init_is_refused(tmp_path):
    # A muscle_run (any duty) was fitted from rest though its first samples read 5.7 bar abs; triangles were refused.
    header, high = RUN_HEADER.format("pressure"), np.full(500, 4.7)  # barg
    for kind, run in (({"kind": "muscle_run"}, (header, [T_RUN, np.full(500, 0.6), high, RISING])),
                      (TRIANGLE, ("t [s],pressure [barg],position [mm]", [T_RUN, high, RISING]))):  # no duty: no phase
        folder = _csv_bench(tmp_path / kind["kind"], {"M": (kind, *run)})
        with pytest.raises(PamjaxInputError, match=r"'M' starts at 571325 Pa abs \(\+4\.7 bar gauge.* logged from the "
                                                   r"middle.*mark it with \"init\": \"unknown\""):
            pj.bench.load_bench(folder, _plant())
    marked = _csv_bench(tmp_path / "marked", {"M": (MIDWAY, header, [T_RUN, np.full(500, 0.6), high, RISING])})
    assert pj.bench.load_bench(marked, _plant()).unknown_starts == ["M"]
    rest = _csv_bench(tmp_path / "rest", {"M": ({"kind": "muscle_run"}, header, AT_REST)})  # a sensor offset: at rest
    assert [e.name for e in pj.bench.load_bench(rest, _plant()).experiments] == ["M"]


@pytest.mark.parametrize("entry, match", [
    ({"p0": 1.01325}, r"'T' p0 must be 'p_atm', 'p_s' or a pressure in Pa ABSOLUTE .*got 1\.01325"),
    ({"p0": True}, r"'T' p0 must be .*got True"),
    ({"p0": 1e9}, r"'T' p0 must be .*got 1000000000\.0"),
    ({"supply_Pa": 5.5e4, "supply_sd_Pa": 1e3}, r"meta\.json: T: supply_Pa = 55000 Pa is not above the atmosphere"),
])
def test_a_tank_start_or_a_supply_reading_that_is_no_absolute_pressure_is_named(tmp_path, entry, match):
    folder = _csv_bench(tmp_path / "b", {"T": ({**TANK[0], **entry}, TANK[1], TANK[2])})
    with pytest.raises(PamjaxInputError, match=match):
        pj.bench.load_bench(folder, _plant())


def test_two_experiments_of_one_name_in_meta_json_are_refused(tmp_path):
    # JSON keeps the last of two keys: two runs of one name were one run, silently.
    folder = _csv_bench(tmp_path / "b", {"T": TANK})
    text = (folder / "meta.json").read_text()
    twice = text.replace('"experiments": {', '"experiments": {"T": {"kind": "tank_charge"}, ')
    (folder / "meta.json").write_text(twice)
    with pytest.raises(PamjaxInputError, match=r"meta\.json: key 'T' is written twice in one table"):
        pj.bench.load_bench(folder, _plant())


def test_the_silenced_presets_exhaust_port_is_what_cv23_and_b23_free():
    """With `mas10_system(silencer=True)` the exhaust port is `valve.exhaust.first` (a silencer in series after it):
    Cv23/b23 mapped to `valve.exhaust.discharge_coefficient`, which `fit` refused as a path the user never wrote."""
    model = presets.mas10_system(valve="pwm", friction="karnopp", silencer=True)
    b = pj.bench.load_bench(ROOT / "pamjax/data/hybrid-reference-bench", model, runs=["E2_u0.50"],
                            fitted_keys=["Cv23", "b23", "Cv12"])
    assert b.free == ["valve.exhaust.first.discharge_coefficient", "valve.exhaust.first.critical_ratio",
                      "valve.inflate.discharge_coefficient"]
    assert any("valve.exhaust.critical_ratio is valve.exhaust.first.critical_ratio" in n for n in b.notes)
    space = pj.ParameterSpace(b.model, b.free)  # what fit builds first: every path is the model's
    assert len(space.initial_values()) == 3
    # read back in the bench's names: Cv23 and b23 were left out of bench_values (and bench_key, --profile Cv23)
    import types

    from pamjax._bench.report import bench_key, bench_values, fitted_labels

    fitted = types.SimpleNamespace(labels=list(b.free), values=[0.4, 0.5, 0.36], standard_errors=[0.01, 0.02, 0.03])
    assert bench_values(fitted, ["Cv23", "b23", "Cv12"]) == ({"Cv23": 0.4, "b23": 0.5, "Cv12": 0.36},
                                                             {"Cv23": 0.01, "b23": 0.02, "Cv12": 0.03})
    assert [bench_key(label) for label in b.free] == ["Cv23", "b23", "Cv12"]
    assert fitted_labels("b23", b.free) == ["valve.exhaust.first.critical_ratio"]


def test_a_payload_in_grams_in_meta_json_is_refused_naming_the_file(tmp_path):
    # "payload_kg": 9600 (grams) loaded as a 9.6 t payload; a config's payload_kg refuses the same number
    run = ({**MIDWAY, "payload_kg": 9600.0}, RUN_HEADER.format("pressure"), RUN_COLUMNS)
    folder = _csv_bench(tmp_path / "b", {"T": TANK, "M": run})
    with pytest.raises(PamjaxInputError, match=r"b/meta\.json.*payload_kg = 9600 kg: more than 1000 kg; that looks "
                                               r"like g"):
        pj.bench.load_bench(folder, _plant())
