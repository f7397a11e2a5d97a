"""Bench directories in the hybrid-reference layout: one `.npz` recording per experiment and a `meta.json` that
describes them (`pamjax/data/hybrid-reference-bench/README.md`: the copy shipped with pamjax).

`meta.json` holds `experiments` (name → kind and conditions: `tank_charge` / `tank_discharge` with `V_tank`, `u`,
`p0`; `muscle_triangle` with `lo`, `hi`, `f_tri`; `muscle_PI` closed-loop runs), `noise` (`p_std_Pa`, `x_std_m`),
`fitted_keys` (the parameters to identify, named as below) and, for simulated benches, the true `params` (never read
here: a fit starts from the model it is given, e.g. the presets). Recordings hold `t` [s], `u` (the duty latched per
PWM period), `p` [Pa abs], `x` [m].

`load_bench` turns such a directory into `Experiment`s for `pamjax.fit`; `BENCH_PARAMETERS` maps the bench's
parameter names to pamjax parameter paths; `bench_values` reads a fit result back in the bench's names.
"""

import dataclasses
import json
import pathlib

import numpy as np

from .._core.errors import PamjaxInputError
from .._physics.signals import Constant, Triangle
from .experiment import Experiment, TankFromModel
from .recording import Recording

# bench name → (pamjax parameter path, label of the value in a FitResult)
BENCH_PARAMETERS = {
    "Cv12": ("valve.inflate.discharge_coefficient", "valve.inflate.discharge_coefficient"),
    "b12": ("valve.inflate.critical_ratio", "valve.inflate.critical_ratio"),
    "Cv23": ("valve.exhaust.discharge_coefficient", "valve.exhaust.discharge_coefficient"),
    "b23": ("valve.exhaust.critical_ratio", "valve.exhaust.critical_ratio"),
    "v0": ("muscle.volume_law.v0", "muscle.volume_law.v0"),
    "v1": ("muscle.volume_law.v1", "muscle.volume_law.v1"),
    **{f"a{i}": ("muscle.force_law.max_force_coefficients", f"a{i}") for i in range(5)},
    "k0": ("muscle.force_law.k0", "muscle.force_law.k0"),
    "k1": ("muscle.force_law.k1", "muscle.force_law.k1"),
    "k2": ("muscle.force_law.k2", "muscle.force_law.k2"),
    "Fc": ("friction.coulomb_force", "friction.coulomb_force"),
    "Cf": ("friction.viscous_coefficient", "friction.viscous_coefficient"),
}
FITTED_KINDS = ("tank_charge", "tank_discharge", "muscle_triangle")
_CHANNEL = {"pressure": "p", "position": "x"}


@dataclasses.dataclass
class Bench:
    """A loaded bench directory: `experiments` (for `pamjax.fit`), `free` (the parameter paths of `fitted_keys`),
    `fitted_keys`, `noise` (channel → standard deviation used as the residual scale), `skipped` (experiment →
    reason), `meta` (the parsed meta.json), `directory`, `rate` (None: as recorded)."""

    experiments: list
    free: list
    fitted_keys: list
    noise: dict
    skipped: dict
    meta: dict
    directory: pathlib.Path
    rate: float | None


def _read_meta(directory):
    directory = pathlib.Path(directory)
    if not directory.is_dir():
        raise PamjaxInputError(f"bench directory {directory} does not exist or is not a directory")
    path = directory / "meta.json"
    if not path.exists():
        raise PamjaxInputError(f"bench directory {directory} has no meta.json (the hybrid-reference layout: "
                               "pamjax/data/hybrid-reference-bench/README.md)")
    try:
        meta = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise PamjaxInputError(f"{path} is not valid JSON: {err}") from err
    if not isinstance(meta.get("experiments"), dict) or not meta["experiments"]:
        raise PamjaxInputError(f"{path} needs an 'experiments' table (name → kind and conditions)")
    return directory, meta


def _free_paths(keys):
    unknown = [k for k in keys if k not in BENCH_PARAMETERS]
    if unknown:
        raise PamjaxInputError(f"fitted_keys {unknown} are not bench parameters pamjax knows; valid: "
                               f"{sorted(BENCH_PARAMETERS)}")
    paths = []
    for k in keys:
        path = BENCH_PARAMETERS[k][0]
        if path not in paths:
            paths.append(path)
    return paths


def _noise_levels(meta, recordings):
    """Noise standard deviations: meta.json's `noise` where given, else estimated from the recordings (1.4826 MAD
    of first differences / √2, the white part of the signal)."""
    given = meta.get("noise", {})
    out = {}
    if "p_std_Pa" in given:
        out["pressure"] = float(given["p_std_Pa"])
    if "x_std_m" in given:
        out["position"] = float(given["x_std_m"])
    for c in ("pressure", "position"):
        if c not in out:
            diffs = [np.diff(r[c]) for r in recordings if c in r.channels and np.ptp(r[c]) > 0]
            if diffs:
                d = np.concatenate(diffs)
                out[c] = float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))
    return out


def load_bench(directory, model, *, rate=None, kinds=FITTED_KINDS, fitted_keys=None, substeps=16):
    """Experiments of a bench directory for `pamjax.fit(model, bench.experiments, bench.free)`.

    **Arguments:**

    - `directory`: a folder with `meta.json` and one `<name>.npz` per experiment.
    - `model`: the system to be fitted (e.g. `pamjax.presets.mas10_system(valve="pwm", friction="karnopp")`); its
      atmospheric and supply pressures set the tank tests' initial pressures (`p0` "p_atm" / "p_s").
    - `rate`: decimate the recordings to this rate [Hz] (`Recording.resampled`: recorded samples, no filter);
      None keeps them as recorded.
    - `kinds`: the experiment kinds to fit (default: tank charge/discharge and the muscle's triangle runs; the
      closed-loop `muscle_PI` runs are left out: pamjax's PWM grid reads a planned duty, not a controller's).
    - `fitted_keys`: bench parameter names to free (default: meta.json's `fitted_keys`).
    - `substeps`: RK4 nodes per PWM period of the fixed grid.

    **Returns:** a `Bench`.
    """
    directory, meta = _read_meta(directory)
    keys = list(meta.get("fitted_keys", [])) if fitted_keys is None else list(fitted_keys)
    if not keys:
        raise PamjaxInputError("no parameters to fit: meta.json has no fitted_keys and none were given")
    free = _free_paths(keys)
    p_atm = float(model.air.atmospheric_pressure)
    p_supply = float(getattr(model.valve, "supply_pressure", np.nan))
    specs, skipped, recordings = [], {}, []
    for name, e in meta["experiments"].items():
        kind = e.get("kind")
        if kind not in kinds:
            skipped[name] = f"kind {kind!r} not fitted (kinds={list(kinds)})"
            continue
        path = directory / f"{name}.npz"
        if not path.exists():
            raise PamjaxInputError(f"bench {directory}: experiment {name!r} has no recording {path.name}")
        rec = Recording.load(path, name=name)
        if rate is not None:
            rec = rec.resampled(rate)
        recordings.append(rec)
        specs.append((name, kind, e, rec))
    noise = _noise_levels(meta, recordings)
    experiments = []
    for name, kind, e, rec in specs:
        if kind in ("tank_charge", "tank_discharge"):
            p0 = {"p_atm": p_atm, "p_s": p_supply}.get(e.get("p0"), e.get("p0"))
            experiments.append(Experiment(
                rec, Constant(float(e["u"])), channels=["pressure"], scales={"pressure": noise["pressure"]},
                build=TankFromModel(float(e["V_tank"])), initial={"pressure": float(p0)}, name=name,
                substeps=substeps))
        else:  # muscle_triangle: from rest at equilibrium, valve off, stuck (the model's default initial state)
            experiments.append(Experiment(
                rec, Triangle(float(e["lo"]), float(e["hi"]), float(e["f_tri"])), channels=["pressure", "position"],
                scales={c: noise[c] for c in ("pressure", "position")}, name=name, substeps=substeps))
    if not experiments:
        raise PamjaxInputError(f"bench {directory}: no experiment of the kinds {list(kinds)}")
    return Bench(experiments, free, keys, noise, skipped, meta, directory, rate)


def bench_values(result, keys):
    """A fit result's values and standard errors by bench name: ({key: value}, {key: std err}) [SI units]."""
    label_index = {label: i for i, label in enumerate(result.labels)}
    values, errors = {}, {}
    for k in keys:
        label = BENCH_PARAMETERS[k][1]
        if label in label_index:
            i = label_index[label]
            values[k], errors[k] = float(result.values[i]), float(result.standard_errors[i])
    return values, errors


def bench_rmse(result):
    """{experiment: {"p": Pa, "x": m}}: the residual RMSE of every fitted experiment, by the bench's channel names."""
    out = {}
    for name, chans in result.channel_errors.items():
        out[name] = {_CHANNEL.get(c, c): float(st["rmse"]) for c, st in chans.items() if "rmse" in st}
    return out
