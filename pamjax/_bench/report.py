"""A fit of a bench directory read back in the bench's terms: the plant's values by the bench's names
(`bench_values`), the rig's nuisances apart from the plant (`bench_nuisance`, `nuisance_table`), each recording's
residual RMSE (`bench_rmse`), and the fit's labels a user's names pick (`fitted_labels`: `--profile Fc,k0`).
`pamjax._bench.load` builds the fit these read."""

import re
from collections.abc import Sequence

from .._core.errors import PamjaxInputError
from .._fit.fit import FitResult
from .._fit.measurement import is_measurement
from .._fit.rig import DEFAULT_GROUP, PLANT_PREFIX, Rig, Sensors, nuisance_report, plant_label
from .load import BENCH_PARAMETERS, CALIBRATION_NAME, GAUGE_NAME, Bench

_CHANNEL = {"pressure": "p", "position": "x"}


def bench_values(result: FitResult, keys: Sequence[str]) -> tuple[dict[str, float], dict[str, float]]:
    """A fit result's values and standard errors by bench name: ({key: value}, {key: std err}) [SI units]. The
    plant's labels are matched with or without a `Rig`'s `plant.` prefix."""
    label_index = {label: i for i, label in enumerate(result.labels)}
    values, errors = {}, {}
    for k in keys:
        i = next((label_index[c] for c in _forms(BENCH_PARAMETERS[k][1]) if c in label_index), None)
        if i is not None:
            values[k], errors[k] = float(result.values[i]), float(result.standard_errors[i])
    return values, errors


def bench_nuisance(result: FitResult, bench: Bench) -> dict:
    """A fit's nuisances in the bench's terms (SI units): `delay_s`, `pressure_offset_Pa` (added to the gauge
    pressure), `pressure_gain` (multiplies it), `position_offset_m`, `supply_pressure_Pa` (run → value), `start` (run
    → pressure_Pa, position_m, velocity_m_s), each fitted one's standard error under `std_err` (same keys), and
    `held` (those not fitted, with their value and why); with a calibrated gain's uncertainty `calibration`
    (pressure_gain, pressure_gain_sd, z), with a reference gauge's supply readings `gauges` (run → supply_Pa,
    supply_sd_Pa, z: fitted − reading in its uncertainties)."""
    report = nuisance_report(result)
    sensors = report["sensors"].get(DEFAULT_GROUP, {})
    base = bench.model.sensors[DEFAULT_GROUP] if isinstance(bench.model, Rig) else Sensors()
    out, se, held = {}, {}, {}
    for field, key in (("delay", "delay_s"), ("pressure_offset", "pressure_offset_Pa"),
                       ("pressure_gain", "pressure_gain"), ("position_offset", "position_offset_m")):
        if field in sensors:
            out[key], se[key] = sensors[field]
        else:
            out[key] = float(getattr(base, field))
            held[key] = ("not identifiable from a rig's runs (a shift of the position origin is absorbed exactly by "
                         "F_max, k0 and v0); held at the calibration given" if field == "position_offset" else
                         "as calibrated (load_bench's pressure_gain, --pressure-gain)" if field in bench.calibrated else
                         "not fitted (nuisance not freed)")
    supply, supply_se, start, start_se = {}, {}, {}, {}
    units = {"pressure": "pressure_Pa", "position": "position_m", "velocity": "velocity_m_s"}
    for run, fields in report["runs"].items():
        for name, (value, err) in fields.items():
            if name == "supply_pressure":
                supply[run], supply_se[run] = value, err
            elif name.startswith("start."):
                key = units[name.split(".", 1)[1]]
                start.setdefault(run, {})[key] = value
                start_se.setdefault(run, {})[key] = err
    out.update(supply_pressure_Pa=supply, start=start)
    se.update(supply_pressure_Pa=supply_se, start=start_se)
    out["std_err"], out["held"] = se, held
    calibration = result.channel_errors.get(CALIBRATION_NAME, {}).get("value")
    if calibration is not None:  # the gain fitted with its calibration: the calibration, its sd, z
        out["calibration"] = {"pressure_gain": calibration["measured"], "pressure_gain_sd": calibration["sd"],
                              "z": calibration["z"]}
    gauges = {run: result.channel_errors.get(GAUGE_NAME.format(run), {}).get("value") for run in supply}
    if any(gauges.values()):  # supplies fitted with a reference gauge's readings: each reading, its sd, z
        out["gauges"] = {run: {"supply_Pa": g["measured"], "supply_sd_Pa": g["sd"], "z": g["z"]}
                         for run, g in gauges.items() if g}
    return out


# Above this relative standard error of the pressure gain the table says what follows from it and how to remove it:
# 0.2 %, below the 0.28-0.42 % that free supplies leave on realistic1-like rigs (benchmarks/RESULTS.md, identify).
GAIN_HINT_SE = 2e-3


def nuisance_table(nuisance: dict) -> str:
    """Text table of `bench_nuisance`'s report: each nuisance, its value ± standard error (or 'held')."""
    se, rows = nuisance["std_err"], []
    for key in ("delay_s", "pressure_offset_Pa", "pressure_gain", "position_offset_m"):
        v = nuisance[key]
        rows.append(f"  {key:<22}{v:>14.6g}  " + (f"± {se[key]:.3g}" if key in se else "held: "
                                                   + nuisance["held"].get(key, "")))
        calibration = nuisance.get("calibration")
        if key == "pressure_gain" and calibration is not None:
            rows[-1] += (f"  (calibrated {calibration['pressure_gain']:.6g} ± {calibration['pressure_gain_sd']:.3g}, "
                         f"fitted {calibration['z']:+.2f} of its uncertainties from it)")
        elif key == "pressure_gain" and se.get(key, 0.0) > GAIN_HINT_SE * abs(v):
            rows[-1] += (f"  (± {100 * se[key] / abs(v):.2f} %: each supply pressure and F_max follow its error; a "
                         "calibrated gain removes that: --pressure-gain (with its uncertainty: --pressure-gain-sd), "
                         "[bench] pressure_gain; docs/fitting.md)")
    for run, v in nuisance["supply_pressure_Pa"].items():
        rows.append(f"  {'supply_pressure_Pa':<22}{v:>14.6g}  ± {se['supply_pressure_Pa'][run]:.3g}  ({run})")
        gauge = nuisance.get("gauges", {}).get(run)
        if gauge is not None:
            rows[-1] += (f"  (gauge {gauge['supply_Pa']:.6g} ± {gauge['supply_sd_Pa']:.3g}, fitted {gauge['z']:+.2f} "
                         "of its uncertainties from it)")
    for run, fields in nuisance["start"].items():
        for key, v in fields.items():
            rows.append(f"  {'start ' + key:<22}{v:>14.6g}  ± {se['start'][run][key]:.3g}  ({run})")
    return "\n".join(rows)


def bench_rmse(result: FitResult) -> dict[str, dict[str, float]]:
    """{experiment: {"p": Pa, "x": m}}: the residual RMSE of every fitted experiment, by the bench's channel names."""
    out = {}
    measured = {e.name for e in (result.experiments or []) if is_measurement(e)}
    for name, chans in result.channel_errors.items():
        if name not in measured and not any("z" in st for st in chans.values()):  # a measurement: not a recording
            out[name] = {_CHANNEL.get(c, c): float(st["rmse"]) for c, st in chans.items() if "rmse" in st}
    return out


_KEYS = {label: key for key, (_, label) in BENCH_PARAMETERS.items()}  # a fit label (no `plant.`) → its bench key
# the index's comma ([1,0]) is not a separator between names
_NAMES = re.compile(r",(?![^\[]*\])")


def _forms(label):
    """The labels a fit may give the bench's `label`: itself and on a `Rig` (`plant.`), each also as the port of a
    series restriction (`valve.exhaust.first.critical_ratio`: a silenced exhaust, `load_bench`'s mapping); Cv23 and
    b23 fitted so were left out of `bench_values`, silently."""
    head, _, leaf = label.rpartition(".")
    series = f"{head}.first.{leaf}" if head else label
    return (label, PLANT_PREFIX + label, series, PLANT_PREFIX + series)


def bench_key(label: str) -> str | None:
    """The bench's name of a fit's label (`plant.friction.coulomb_force` or `friction.coulomb_force` → `Fc`; a
    series restriction's port, `valve.exhaust.first.…`, as its restriction's), or None where the bench has no name
    for it (a nuisance, a parameter outside `BENCH_PARAMETERS`)."""
    plain = plant_label(label)
    return _KEYS.get(plain, _KEYS.get(plain.replace(".first.", ".")))


def fitted_labels(names: str | Sequence[str], labels: Sequence[str], where: str = "names") -> list[str]:
    """The fit's `labels` that `names` picks: 'all' (every one), or bench keys (`Fc`, `k0`: `BENCH_PARAMETERS`) and
    labels, as a list or one comma-separated string (`"Fc,plant.muscle.force_law.k1"`). A name that picks none is
    named with what can be given (`where`: the argument, e.g. `--profile`), before any work."""
    labels = list(labels)
    given = [n.strip() for n in (_NAMES.split(names) if isinstance(names, str) else names) if n.strip()]
    if given == ["all"]:
        return labels
    fitted = {bench_key(label) for label in labels}
    what = (f"give bench keys ({', '.join(k for k in BENCH_PARAMETERS if k in fitted)}), " if fitted - {None} else
            "give ") + f"the fit's labels ({', '.join(labels)}) or 'all'"
    out = []
    for name in given:
        label = BENCH_PARAMETERS[name][1] if name in BENCH_PARAMETERS else name
        match = [lbl for lbl in labels if lbl in _forms(label)]
        if not match:
            raise PamjaxInputError(f"{where}: {name!r} is not a fitted parameter; {what}")
        out += [m for m in match if m not in out]
    if not out:
        raise PamjaxInputError(f"{where}: {names!r} names no parameter; {what}")
    return out
