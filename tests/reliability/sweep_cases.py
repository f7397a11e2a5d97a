"""Cases of the file and command-line catalogue (`bad_inputs_cli.py`'s format and verdicts) for two defects of
issue 33: sweeps of stick-slip plants, and the gradient check's finite-difference reference.

- "sweep": `pamjax.sweep` and `pamjax sweep` (maps, steady state, frequency response) of a `KarnoppFriction` plant
  kept the payload stuck at its start (−4.69 mm at every duty, a flat map and a Bode gain of 1e-18 m), status 0,
  while `simulate` moves it by tens of mm. Each case compares every sweep point with its own `simulate` (a correct
  result), or expects the named refusal of a scheme that cannot see the friction's events.
- "gradients": `benchmarks/reliability.py` failed 4 of 20 gradient sets because its finite differences (steps
  1e-4..1e-6 θ) measured the adaptive solver's noise, not the gradient; the case checks the parameters it failed on.

Each case is `name → (class, expect, run, name_in_message)` as in `bad_inputs_cli.CASES`; `register()` adds them
there, so `bad_inputs_cli.verdict` judges them and `benchmarks/reliability.py` counts them in `workflow_cases=`
(it registers every `tests/reliability/*_cases.py`).
"""

import csv
import pathlib

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import pamjax
from pamjax import presets

from .bad_inputs_cli import call, cli
from .helpers import random_pwm_problem

E, R = "error", "result"
DUTIES = np.array([0.3, 0.6, 0.9])
TS = np.linspace(0.0, 1.5, 151)  # s: the payload breaks free and rises
# A sweep point runs the same program as its own `simulate`: equal to round-off (1e-16 m, 1e-10 Pa measured). A
# stuck payload is tens of mm off.
POSITION_TOL = 1e-10  # m
PRESSURE_TOL = 1e-4  # Pa


def _karnopp(valve):
    return presets.mas10_system(valve=valve, friction="karnopp")


def _python_sweep(valve):
    """Whole trajectories of a stick-slip sweep equal to `simulate`, point by point, and the payload moves."""
    system = _karnopp(valve)
    r = pamjax.sweep(system, pamjax.Constant(0.5), TS, {"signal.value": DUTIES}, progress=False)
    for k, d in enumerate(DUTIES):
        traj = pamjax.simulate(system, pamjax.Constant(float(d)), TS)
        if not (np.max(np.abs(r["position"][k] - np.asarray(traj.position))) < POSITION_TOL
                and np.max(np.abs(r["pressure"][k] - np.asarray(traj.pressure))) < PRESSURE_TOL):
            return False
    return bool(r.status.max() == 0 and np.min(r["position"][:, -1] - r["position"][:, 0]) > 5e-3)


def _model_file(folder):
    path = pathlib.Path(folder) / "model.json"
    pamjax.save_model(path, _karnopp("averaged"))  # the kind of model `pamjax fit examples/fit_example.toml` writes
    return path


def _column(path, name):
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    return np.array([float(row[name]) for row in rows])


def _cli_steady_state(folder):
    """`pamjax sweep` steady_state of a stick-slip model file: every row the mean of its own `simulate`."""
    _model_file(folder)
    config = pathlib.Path(folder) / "ss.toml"
    config.write_text('kind = "steady_state"\n[model]\nfile = "model.json"\n[sweep]\ncommands = [0.3, 0.6, 0.9]\n'
                      "horizon = 1.5\nwindow = 0.5\n")
    status, _ = cli("sweep", config, "--out", pathlib.Path(folder) / "out", "--no-plot", "--cpu-devices", "1")
    if status != 0:
        return False
    csv_path = pathlib.Path(folder) / "out" / "sweep.csv"
    position, statuses = _column(csv_path, "position_m"), _column(csv_path, "status")
    system = _karnopp("averaged")
    last = TS >= 1.0 - 1e-12
    expected = [np.trapezoid(np.asarray(pamjax.simulate(system, pamjax.Constant(float(d)), TS).position)[last],
                             TS[last]) / 0.5 for d in DUTIES]  # the window's time average (WindowMean)
    return bool(np.all(statuses == 0) and np.max(np.abs(position - expected)) < POSITION_TOL)


def _cli_frequency_response(folder):
    """`pamjax sweep` frequency_response of a stick-slip model file: each gain that of its own `simulate`'s Fourier
    coefficient (the same window weights), and not ~0."""
    from pamjax._sweep.maps import _FourierIntegral

    _model_file(folder)
    config = pathlib.Path(folder) / "fr.toml"
    config.write_text('kind = "frequency_response"\n[model]\nfile = "model.json"\n[sweep]\nfrequencies = [1.0, 2.5]\n'
                      "settle_periods = 1\nperiods = 1\nsamples_per_period = 20\n")
    status, _ = cli("sweep", config, "--out", pathlib.Path(folder) / "out", "--no-plot", "--cpu-devices", "1")
    if status != 0:
        return False
    gain = _column(pathlib.Path(folder) / "out" / "sweep.csv", "position_gain_m")
    system = _karnopp("averaged")
    ts = np.linspace(0.0, 2.0, 101)  # frequency_response's grid: 2 periods of 1 Hz, 20 samples per 2.5 Hz period
    expected = []
    for f in (1.0, 2.5):
        signal = pamjax.Sine(0.5, 0.2, f)
        traj = pamjax.simulate(system, signal, ts)
        w = np.asarray(_FourierIntegral(1).weights(ts, system, signal))
        expected.append(abs(w @ np.asarray(traj.position)) / abs(w @ np.asarray(traj.command)))
    return bool(np.all(gain > 1e-3) and np.allclose(gain, expected, rtol=1e-8))


def _friction_gradients(folder):
    """Reverse mode against central differences within 1e-4 on the parameters benchmarks/reliability.py failed on
    (set 7: F_c 1.1e-3, C_f), through an adaptive solve of the smoothed PWM plant (5 periods, rtol 1e-12)."""
    system, signal = random_pwm_problem(seed=7)
    ts = jnp.linspace(0.0, 0.1, 6)

    def loss(tree, adjoint):
        s = eqx.tree_at(lambda s: (s.friction.coulomb_force, s.friction.viscous_coefficient), system, tree)
        traj = pamjax.unchecked.solve(s, signal, ts, None, 0.0, rtol=1e-12, atol=1e-12, adjoint=adjoint,
                                      max_steps=100_000)
        return jnp.mean((traj.position / 1e-2) ** 2) + jnp.mean((traj.pressure / 1e5) ** 2)

    report = pamjax.gradient_check(loss, (system.friction.coulomb_force, system.friction.viscous_coefficient))
    return bool(report["error_fd"].max() < 1e-4 and report["error_modes"].max() < 1e-6)


CASES = {
    "sweep stick-slip averaged valve (Python)": ("sweep", R, lambda d: _python_sweep("averaged"), None),
    "sweep stick-slip PWM valve (Python)": ("sweep", R, lambda d: _python_sweep("pwm"), None),
    "sweep stick-slip model file, steady_state (CLI)": ("sweep", R, _cli_steady_state, None),
    "sweep stick-slip model file, frequency_response (CLI)": ("sweep", R, _cli_frequency_response, None),
    "sweep stick-slip with a scheme blind to events": ("sweep", E, lambda d: call(
        pamjax.sweep, _karnopp("averaged"), pamjax.Constant(0.5), TS, {"signal.value": DUTIES}, method="rodas5a",
        progress=False), "it is hybrid"),
    "gradients F_c, C_f through an adaptive PWM solve": ("gradients", R, _friction_gradients, None),
}


def register():
    """Add these cases to `bad_inputs_cli.CASES` (idempotent); returns their names."""
    from . import bad_inputs_cli

    bad_inputs_cli.CASES.update(CASES)
    return sorted(CASES)
