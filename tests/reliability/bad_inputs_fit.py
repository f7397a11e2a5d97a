"""Bad inputs of the fitting workflow (recordings, configs, experiments, fit specifications), in the format of
`CORE_CASES` (`bad_inputs.py`): name → (zero-argument callable that must raise a ValueError subclass — a
`pamjax.PamjaxInputError` — before any solve, substring the message must contain).

`FILE_CASES` are the results files that must never be replaced without being asked: each raises `FileExistsError`
(an OSError, not a ValueError) naming `overwrite`. Files are made in a temporary folder, removed afterwards.
"""

import pathlib
import tempfile

import jax.numpy as jnp
import numpy as np

import pamjax
from pamjax import presets
from pamjax._cli.fit import load_config

T = np.linspace(0.0, 1.0, 5)
P = np.full(5, 3e5)  # Pa, absolute


def _force_map():
    x, p = np.meshgrid(np.linspace(0.0, 0.06, 3), 101325.0 + np.array([2e5, 4e5]), indexing="ij")
    f = np.asarray(presets.mas10_muscle().static_force(jnp.asarray(x.ravel()), jnp.asarray(p.ravel()), pamjax.Air()))
    return pamjax.bench.ForceMapExperiment(x.ravel(), p.ravel(), np.maximum(f, 0.0), scale=2.0)


def _fit(free=("force_law.k0",), experiments=None, **kwargs):
    """A fit of the MAS-10 muscle to a small static force map (no ODE) with one bad argument."""

    def run():
        exps = [_force_map()] if experiments is None else experiments()
        return pamjax.fit(presets.mas10_muscle(), exps, list(free) if not isinstance(free, str) else free,
                          progress=False, **kwargs)

    return run


def _experiment(**kwargs):
    rec = pamjax.Recording(T, dict(pressure=P, position=np.zeros(5)))
    return lambda: pamjax.Experiment(rec, pamjax.Constant(0.5), **kwargs)


def _config(text):
    """Write `text` as a config in a temporary folder and load it."""

    def run():
        with tempfile.TemporaryDirectory() as d:
            path = pathlib.Path(d) / "fit.toml"
            path.write_text(text)
            return load_config(path)

    return run


def _in_tmp(make):
    """Run `make(folder)` in a temporary folder (for file formats and existing files)."""

    def run():
        with tempfile.TemporaryDirectory() as d:
            return make(pathlib.Path(d))

    return run


def _write_csv(folder, text):
    (folder / "r.csv").write_text(text)
    return pamjax.Recording.load(folder / "r.csv")


_EXPERIMENT_TOML = '\n[[experiment]]\nfile = "r.csv"\n'

FIT_CASES = {
    # recordings
    "recording NaN row": (lambda: pamjax.Recording(T, dict(pressure=[3e5, 3e5, np.nan, 3e5, 3e5])), "row 2"),
    "recording NaN names channel": (lambda: pamjax.Recording(T, dict(position=[0, 0, 0, np.inf, 0])), "'position'"),
    "recording time not increasing": (lambda: pamjax.Recording([0.0, 0.2, 0.1, 0.3, 0.4], dict(pressure=P)),
                                      "strictly increasing"),
    "recording NaN time": (lambda: pamjax.Recording([0.0, np.nan, 0.2, 0.3, 0.4], dict(pressure=P)),
                           "t must be finite"),
    "recording length mismatch": (lambda: pamjax.Recording(T, dict(pressure=P[:4])), "'pressure' has shape"),
    "recording pressure in bar": (lambda: pamjax.Recording(T, dict(pressure=np.full(5, 3.0))), "ABSOLUTE"),
    "recording gauge pressure": (lambda: pamjax.Recording(T, dict(pressure=np.linspace(-2e4, 4e5, 5))), "GAUGE"),
    "recording pressure unit kPa": (lambda: pamjax.Recording(T, dict(pressure=P), units=dict(pressure="kPa")),
                                    "ABSOLUTE pressure in Pa"),
    "recording no channels": (lambda: pamjax.Recording(T, {}), "channel"),
    "recording file type": (lambda: pamjax.Recording.load("bench.xlsx"), ".csv, .npz or .mat"),
    "recording CSV ragged row": (_in_tmp(lambda d: _write_csv(d, "t [s],pressure [Pa]\n0,3e5\n0.1,3e5,7\n")),
                                 "data row 1"),
    "recording CSV without time": (_in_tmp(lambda d: _write_csv(d, "pressure [Pa]\n3e5\n3e5\n")), "'t'"),
    "recording missing channel": (lambda: pamjax.Recording(T, dict(pressure=P))["position"], "no channel 'position'"),
    "filter above Nyquist": (lambda: pamjax.Recording(T, dict(pressure=P)).filtered(10.0), "cutoff_hz"),
    # configs
    "config unknown top-level key": (_config('[model]\n[fit]\nfree = ["payload_mass"]\n[solver]\n'), "solver"),
    "config unknown [fit] key": (_config('[fit]\nfree = ["payload_mass"]\nmax_iterations = 5\n'), "max_iterations"),
    "config unknown [model] key": (_config('[model]\nvalve = "averaged"\n[fit]\nfree = ["payload_mass"]\n'), "valve"),
    "config unknown experiment key": (_config('[fit]\nfree = ["payload_mass"]\n' + _EXPERIMENT_TOML + "noise = 1\n"),
                                      "noise"),
    "config unknown preset": (_config('[model]\npreset = "mas20"\n[fit]\nfree = ["payload_mass"]\n'), "preset"),
    "config without free": (_config("[fit]\nmax_steps = 5\n"), "free"),
    "config without experiments": (_config('[fit]\nfree = ["payload_mass"]\n'), "[[experiment]]"),
    "config missing file": (lambda: load_config("/nonexistent/fit.toml"), "does not exist"),
    # experiments
    "experiment scale for uncompared channel": (_experiment(channels=["pressure"], scales=dict(position=1e-4)),
                                                "scales"),
    "experiment zero scale": (_experiment(scales=dict(pressure=0.0)), "scales['pressure']"),
    "experiment validation fraction 1": (_experiment(validation_fraction=1.0), "validation_fraction"),
    "experiment unknown channel": (_experiment(channels=["force"]), "no channel 'force'"),
    "experiment not a recording": (lambda: pamjax.Experiment({"t": T}, pamjax.Constant(0.5)), "recording"),
    "force map gauge pressure": (lambda: pamjax.bench.ForceMapExperiment([0.0, 0.01], [0.0, 3e4], [10.0, 5.0]),
                                 "ABSOLUTE"),
    "force map length mismatch": (lambda: pamjax.bench.ForceMapExperiment([0.0, 0.01], [3e5, 3e5], [10.0]),
                                  "one length"),
    "force map NaN force": (lambda: pamjax.bench.ForceMapExperiment([0.0, 0.01], [3e5, 3e5], [10.0, np.nan]), "forces"),
    "synthetic negative noise": (lambda: pamjax.synthetic_recording(
        presets.mas10_tank_system("averaged"), pamjax.Constant(0.5), T, noise=dict(pressure=-1.0)), "noise"),
    # fit specifications
    "fit unknown parameter": (_fit(free=["force_law.k9"]), "unknown parameter 'force_law.k9'"),
    "fit unknown parameter lists valid": (_fit(free=["force_law.k9"]), "force_law.k0"),
    "fit malformed path": (_fit(free=["force_law..k0"]), "malformed"),
    "fit index out of range": (_fit(free=["force_law.max_force_coefficients[7]"]), "out of range"),
    "fit free as a string": (_fit(free="force_law.k0"), "free"),
    "fit empty free": (_fit(free=[]), "free"),
    "fit parameter named twice": (_fit(free=["force_law.k0", "force_law.k0"]), "named twice"),
    "fit unknown transform": (_fit(free=[{"path": "force_law.k0", "transform": "sqrt"}]), "transform"),
    "fit unknown free key": (_fit(free=[{"path": "force_law.k0", "prior": 1.0}]), "unknown keys"),
    "fit bounds exclude start": (_fit(free=[{"path": "force_law.k0", "bounds": (200.0, 300.0)}]), "bounds"),
    "fit log of negative start": (_fit(free=[{"path": "min_position", "transform": "log"}]), "positive start"),
    "fit logistic without bounds": (_fit(free=[{"path": "force_law.k0", "transform": "logistic"}]), "needs bounds"),
    "fit empty experiments": (_fit(experiments=lambda: []), "experiments"),
    "fit not an experiment": (_fit(experiments=lambda: ["bench.csv"]), "experiments"),
    "fit duplicate experiment names": (_fit(experiments=lambda: [_force_map(), _force_map()]), "unique"),
    "fit max_steps 0": (_fit(max_steps=0), "max_steps"),
    "fit max_steps negative": (_fit(max_steps=-5), "max_steps"),
    "fit max_steps float": (_fit(max_steps=10.5), "max_steps"),
    "fit checkpoint not npz": (_fit(checkpoint="/tmp/state.json"), "checkpoint"),
    "fit resume missing": (_fit(resume="/nonexistent/state.npz"), "resume"),
}

FILE_CASES = {
    "fit out exists": _in_tmp(lambda d: (d / "fit.json").write_text("{}") and pamjax.fit(
        presets.mas10_muscle(), [_force_map()], ["force_law.k0"], progress=False, out=d / "fit.json")),
    "fit checkpoint exists": _in_tmp(lambda d: (d / "state.npz").write_bytes(b"x") and pamjax.fit(
        presets.mas10_muscle(), [_force_map()], ["force_law.k0"], progress=False, checkpoint=d / "state.npz")),
    "recording CSV exists": _in_tmp(lambda d: (d / "r.csv").write_text("x") and pamjax.Recording(
        T, dict(pressure=P)).to_csv(d / "r.csv")),
    "recording NPZ exists": _in_tmp(lambda d: (d / "r.npz").write_bytes(b"x") and pamjax.Recording(
        T, dict(pressure=P)).to_npz(d / "r.npz")),
}
