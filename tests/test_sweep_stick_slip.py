"""Sweeps of hybrid plants (exact stick-slip friction, `KarnoppFriction`): every lane equals its own
`pamjax.simulate` (the fixed RK4 grid with the stick/slip events located inside the step), for whole trajectories,
the reductions, the steady-state map and the frequency response, from Python and from `pamjax sweep`; the schemes
that cannot see the events are refused by name.

The defect these guard against: sweeps stepped the hybrid plant with schemes that never switch its friction mode,
so the payload stayed stuck at its start (−4.69 mm at every duty, 479 N of "static friction" against F_c = 16 N),
status 0, while `simulate` moves it by tens of mm. The oracle is `simulate` itself, lane by lane (its own
event-driven solve, checked against SciPy in tests/test_grid.py)."""

import csv

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._core.errors import PamjaxInputError
from pamjax._sweep.maps import _FourierIntegral

DUTIES = np.array([0.3, 0.6, 0.9])
TS = np.linspace(0.0, 1.5, 151)  # s: breaks free, rises, and (PWM at 0.9) sticks again
# Each lane runs the same program as its own `simulate`, so they agree to round-off (measured: 1e-16 m, 1e-10 Pa);
# a stuck payload is off by tens of mm and hundreds of kPa.
POSITION_TOL = 1e-10  # m
PRESSURE_TOL = 1e-4  # Pa


def _karnopp(valve):
    return presets.mas10_system(valve=valve, friction="karnopp")


def _check_channels(result, index, traj, channels, reduce=None):
    for c in channels:
        ref = np.asarray(traj.channel(c))
        if reduce is not None:
            ref = np.asarray(reduce.weights(TS, None, None)) @ ref
        tol = {"position": POSITION_TOL, "pressure": PRESSURE_TOL}.get(c, 1e-9 * max(1.0, np.max(np.abs(ref))))
        np.testing.assert_allclose(result[c][index], ref, rtol=0, atol=tol, err_msg=f"{c} at point {index}")


@pytest.mark.parametrize("valve", ["averaged", "pwm"])
def test_every_lane_equals_its_own_simulate(valve):
    system = _karnopp(valve)
    over = {"signal.value": DUTIES[:, None]}
    if valve == "pwm":  # lanes with different PWM periods: the grid has as many periods as the fastest lane needs
        over["valve.pwm_frequency"] = np.array([40.0, 50.0])[None, :]
    r = pamjax.sweep(system, pamjax.Constant(0.5), TS, over, progress=False)
    assert np.all(r.status == 0)
    assert r.method == ("pwm" if valve == "pwm" else "grid")
    moved = []
    for index in np.ndindex(r.status.shape):
        lane = system
        if valve == "pwm":
            lane = eqx.tree_at(lambda s: s.valve.pwm_frequency, system,
                               jnp.asarray(r.over["valve.pwm_frequency"][index]))
        traj = pamjax.simulate(lane, pamjax.Constant(float(r.over["signal.value"][index])), TS)
        _check_channels(r, index, traj, r.channels)
        moved.append(r["position"][index][-1] - r["position"][index][0])
    # the payload moves (it stayed at -4.69 mm when the sweep ignored the friction's events)
    assert min(moved) > 5e-3, moved


def test_reductions_of_a_hybrid_lane_equal_those_of_simulate():
    system = _karnopp("averaged")
    trajs = [pamjax.simulate(system, pamjax.Constant(float(d)), TS) for d in DUTIES]
    for reduce in (pamjax.FinalValue(), pamjax.WindowMean(0.5)):
        r = pamjax.sweep(system, pamjax.Constant(0.5), TS, {"signal.value": DUTIES}, reduce=reduce,
                         channels=("position", "pressure", "friction_force"), progress=False)
        for k, traj in enumerate(trajs):
            _check_channels(r, k, traj, r.channels, reduce)
    # friction at the end of the run: sliding (|F| ≥ F_c = 16 N less the viscous part), not a stuck payload held by
    # hundreds of newtons
    assert np.all(np.abs(r["friction_force"]) < 20.0)


def test_steady_state_map_and_frequency_response_of_a_hybrid_plant_equal_simulate():
    system = _karnopp("averaged")
    horizon, window = 1.5, 0.5
    ss = pamjax.steady_state_map(system, DUTIES, horizon=horizon, window=window, progress=False)
    ts = np.linspace(0.0, horizon, 151)  # the map's default: 0.01 s without a switching valve
    last = ts >= horizon - window - 1e-12
    mean = lambda y: np.trapezoid(y[last], ts[last]) / window  # noqa: E731  (WindowMean: the trapezoid rule)
    for k, d in enumerate(DUTIES):
        traj = pamjax.simulate(system, pamjax.Constant(float(d)), ts)
        assert abs(ss["position"][k] - mean(np.asarray(traj.position))) < POSITION_TOL
        assert abs(ss["pressure"][k] - mean(np.asarray(traj.pressure))) < PRESSURE_TOL
    assert np.all(np.diff(ss["position"]) > 1e-3)  # it rises with duty

    frequencies = np.array([1.0, 2.5])
    fr = pamjax.frequency_response(system, frequencies, settle_periods=1, periods=1, samples_per_period=20,
                                   progress=False)
    r = fr["result"]
    assert np.all(r.status == 0)
    for k, f in enumerate(frequencies):
        signal = pamjax.Sine(0.5, 0.2, float(f))
        traj = pamjax.simulate(system, signal, r.t)
        w = np.asarray(_FourierIntegral(1).weights(r.t, system, signal))
        for c, tol in (("position", POSITION_TOL), ("pressure", PRESSURE_TOL), ("command", 1e-12)):
            assert abs(r[c][k] - w @ np.asarray(traj.channel(c))) < tol, (c, f)
    gain = fr["position"]["gain"]
    assert np.all(gain > 1e-3), gain  # m per unit duty: it was 1e-18 when the payload never moved


@pytest.mark.parametrize("method", ["rodas5a", "ros2", "ros2a", "adaptive"])
def test_schemes_without_events_are_refused_by_name(method):
    with pytest.raises(PamjaxInputError, match=rf"method='{method}' cannot sweep this system: it is hybrid"):
        pamjax.sweep(_karnopp("averaged"), pamjax.Constant(0.5), TS, {"signal.value": DUTIES}, method=method,
                     progress=False)


def test_rk4_step_of_a_hybrid_sweep_is_simulates_grid_step():
    system = _karnopp("averaged")
    r = pamjax.sweep(system, pamjax.Constant(0.5), TS, {"signal.value": DUTIES[1:2]}, method="rk4", dt=2e-3,
                     reduce=pamjax.FinalValue(), progress=False)
    assert r.dt == pytest.approx(2e-3)
    traj = pamjax.simulate(system, pamjax.Constant(float(DUTIES[1])), TS, grid_step=2e-3)
    assert abs(r["position"][0] - float(traj.position[-1])) < POSITION_TOL


def _rows(path):
    with open(path, newline="") as f:
        return [row for row in csv.DictReader(line for line in f if not line.startswith("#"))]


def test_cli_sweeps_a_fitted_stick_slip_model_file(tmp_path):
    from pamjax._cli.main import main

    system = _karnopp("averaged")
    pamjax.save_model(tmp_path / "model.json", system)  # what `pamjax fit examples/fit_example.toml` writes
    config = tmp_path / "ss.toml"
    config.write_text('kind = "steady_state"\n[model]\nfile = "model.json"\n[sweep]\ncommands = [0.3, 0.6, 0.9]\n'
                      "horizon = 1.5\nwindow = 0.5\n")
    assert main(["sweep", str(config), "--out", str(tmp_path / "ss"), "--cpu-devices", "1", "--no-plot"]) == 0
    rows = _rows(tmp_path / "ss" / "sweep.csv")
    ref = pamjax.steady_state_map(system, DUTIES, horizon=1.5, window=0.5, progress=False)
    assert [float(r["status"]) for r in rows] == [0, 0, 0]
    position = np.array([float(r["position_m"]) for r in rows])
    np.testing.assert_allclose(position, ref["position"], rtol=0, atol=POSITION_TOL)
    assert np.ptp(position) > 0.04  # flat at -4.69 mm when the sweep ignored the friction's events

    config = tmp_path / "fr.toml"
    config.write_text('kind = "frequency_response"\n[model]\nfile = "model.json"\n[sweep]\nfrequencies = [1.0, 2.5]\n'
                      "settle_periods = 1\nperiods = 1\nsamples_per_period = 20\n")
    assert main(["sweep", str(config), "--out", str(tmp_path / "fr"), "--cpu-devices", "1", "--no-plot"]) == 0
    rows = _rows(tmp_path / "fr" / "sweep.csv")
    ref = pamjax.frequency_response(system, np.array([1.0, 2.5]), settle_periods=1, periods=1, samples_per_period=20,
                                    progress=False)
    gain = np.array([float(r["position_gain_m"]) for r in rows])
    np.testing.assert_allclose(gain, ref["position"]["gain"], rtol=1e-9)
    assert np.all(gain > 1e-3)  # 1e-18 m per unit duty before


def test_an_exact_edge_valve_is_swept_on_the_pwm_grid_as_simulate_steps_it():
    # The exact-edge valve (mode "exact") jumps at its edges. Swept with the switching valve's fixed RK4 step, the
    # jumps fell inside the steps and the tank pressure after 2 s was 90-180 Pa off the exact solution, status 0. Its
    # lanes now run on the PWM-synchronous grid, the edges nodes of the grid: each equals `simulate(stepping="pwm")`
    # and lies within a few Pa of the exact-edge adaptive solve at tight tolerance.
    system = presets.mas10_system(valve="exact")  # smooth friction: no events, only the valve's edges
    ts = np.linspace(0.0, 2.0, 21)
    r = pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": np.array([0.2, 0.4])},
                     reduce=pamjax.FinalValue(), progress=False)
    assert r.method == "pwm" and np.all(r.status == 0)
    for k, u in enumerate((0.2, 0.4)):
        grid = pamjax.simulate(system, pamjax.Constant(u), ts, stepping="pwm")
        assert abs(r["pressure"][k] - float(grid.pressure[-1])) < PRESSURE_TOL
        assert abs(r["position"][k] - float(grid.position[-1])) < POSITION_TOL
        tight = pamjax.simulate(system, pamjax.Constant(u), ts, rtol=1e-10, atol=1e-10)
        assert abs(r["pressure"][k] - float(tight.pressure[-1])) < 5.0, u  # Pa (docs/performance.md: K = 16)
    with pytest.raises(PamjaxInputError, match=r"method='rodas5a' cannot sweep this system: its valve switches at "
                                               r"exact edges"):
        pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": np.array([0.2])}, method="rodas5a",
                     progress=False)


def test_cli_sweeps_an_exact_edge_model_file_and_refuses_its_flow_surface(tmp_path, capsys):
    from pamjax._cli.main import main

    system = presets.mas10_system(valve="exact")
    pamjax.save_model(tmp_path / "model.json", system)
    config = tmp_path / "ss.toml"
    config.write_text('kind = "steady_state"\n[model]\nfile = "model.json"\n[sweep]\ncommands = [0.3, 0.6]\n'
                      "horizon = 1.0\nwindow = 0.5\n")
    assert main(["sweep", str(config), "--out", str(tmp_path / "ss"), "--cpu-devices", "1", "--no-plot"]) == 0
    rows = _rows(tmp_path / "ss" / "sweep.csv")
    ref = pamjax.steady_state_map(system, np.array([0.3, 0.6]), horizon=1.0, window=0.5, progress=False)
    np.testing.assert_allclose([float(r["pressure_pa_abs"]) for r in rows], ref["pressure"], rtol=1e-12)
    config = tmp_path / "fs.toml"
    config.write_text('kind = "flow_surface"\n[model]\nfile = "model.json"\n')
    assert main(["sweep", str(config), "--out", str(tmp_path / "fs"), "--no-plot"]) == 2
    assert "flow_surface' maps a smoothed switching valve" in capsys.readouterr().err
