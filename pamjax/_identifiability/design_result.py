"""`DesignResult`: what `pamjax.design_experiment` returns (the signal, predicted standard errors, constraints), with
its CSV, JSON, table and figure."""

import dataclasses
import math

import jax.numpy as jnp
import numpy as np

from .._core import jsonio
from .._core.errors import PamjaxInputError
from .._core.paths import writable_path
from .._physics.signals import Sampled
from .design_objective import FORCE_UNIT, PRESSURE_UNIT, STEP_UNIT, STROKE_UNIT, force_floor, on_lower_stop


def short_label(label):
    """A parameter's label by its last two parts (`inflate.discharge_coefficient`, `force_law.k0`; `a0` as it is),
    as the design's figure and `pamjax design` name it: the last alone would name the valve's two paths alike."""
    return ".".join(label.split(".")[-2:])


class PamjaxDesignWarning(UserWarning):
    """A design that ends outside its limits (`DesignResult.constraints["violations"]` says which)."""


# How far the run at the fit's resolution (1 kHz, 16 substeps) may pass a limit that the objective (250 Hz, 4 substeps)
# keeps: the objective samples a 20 ms PWM period 5 times, so the PWM ripple's peaks between its samples go unseen
# (measured: 2.1 kPa on the 5e-5 m³ tank, tests/test_design.py; the force follows the pressure at ~1 N per kPa)
VERIFY_TOLERANCE = dict(stroke=1e-4, pressure=5e3, force=5.0)  # m, Pa, N


def worst_violation(aux):
    """The largest constraint violation in its penalty's units (mm, kPa, duty %, N)."""
    return max(float(aux["worst_stroke"]) / STROKE_UNIT, float(aux["worst_pressure"]) / PRESSURE_UNIT,
               float(aux["worst_step"]) / STEP_UNIT, float(aux["worst_force"]) / FORCE_UNIT)


def _range(a):
    return None if a is None else [float(np.min(a)), float(np.max(a))]


def _worst(values, lo, hi):
    """The largest excursion of `values` below `lo` or above `hi` (0 when within; None when not predicted)."""
    if values is None:
        return None
    values = np.asarray(values, dtype=float)
    return float(max(np.max(lo - values, initial=0.0), np.max(values - hi, initial=0.0), 0.0))


def _force_margin(force, position, setup):
    """(the smallest eq. 7 force where the payload hangs free, the smallest where it rests on the lower stop, the
    largest shortfall below `force_floor`'s floor); Nones where not predicted, or the payload never there."""
    if force is None or position is None or setup["min_force"] is None:
        return None, None, None
    force, position = np.asarray(force, dtype=float), np.asarray(position, dtype=float)
    stop = float(setup["system"].muscle.min_position)
    on = on_lower_stop(position, stop)
    floor = force_floor(position, stop, setup["min_force"], xp=np)
    return (float(force[~on].min()) if np.any(~on) else None, float(force[on].min()) if np.any(on) else None,
            float(max(np.max(floor - force), 0.0)))


def _force_lines(free, stop, f_min):
    """The violated force limits, one line each, from the smallest forces off and on the lower stop."""
    lines = []
    if free is not None and free < f_min - 1e-9:
        lines.append(f"min_force: eq. 7's force down to {free:.1f} N where the payload hangs free, limit {f_min:g} N "
                     "(the muscle near slack)")
    if stop is not None and stop < min(f_min, 0.0) - 1e-9:
        lines.append(f"min_force: eq. 7's force down to {stop:.1f} N with the payload on the lower stop: the muscle "
                     "slack there (the volume law holds only while it is taut)")
    return lines


def constraints_report(aux, setup, verified=None):
    """The `constraints` report of a design: the limits, the predicted extremes at the objective's samples and, when
    verified, at the fit's resolution, and whether every limit holds (within `VERIFY_TOLERANCE` at the fit's
    resolution, the objective's own resolution limit)."""
    # on the host: NumPy reductions of a JAX array would each compile a program
    duty, position, pressure, force = (None if aux.get(k) is None else np.asarray(aux[k])
                                       for k in ("duty", "position", "pressure", "force"))
    thresholds = setup["thresholds"]
    out = dict(
        duty_band=list(setup["duty_band"]), switching_thresholds=list(thresholds), duty_margin=setup["duty_margin"],
        duty_limits=list(setup["band"]), duty_windows=[list(w) for w in setup["windows"]], duty_range=_range(duty),
        threshold_distance=(float(np.min(np.abs(duty[:, None] - np.asarray(thresholds)[None, :])))
                            if thresholds else None),
        largest_duty_step=float(np.max(np.abs(np.diff(duty)))) if duty.size > 1 else 0.0,
        max_duty_step=setup["max_duty_step"],
        stroke_limits=None if setup["limits"] is None else [float(s) for s in setup["limits"]],
        position_range=_range(position), max_pressure=setup["max_pressure"], pressure_range=_range(pressure),
        min_force=setup["min_force"], force_range=_range(force), feasible=worst_violation(aux) <= 1e-9)
    out["free_force_min"], out["stop_force_min"], _ = _force_margin(force, position, setup)
    if verified is not None:
        lo_x, hi_x = setup["limits"] if setup["limits"] is not None else (-np.inf, np.inf)
        p_max = np.inf if setup["max_pressure"] is None else setup["max_pressure"]
        f_min = -np.inf if setup["min_force"] is None else setup["min_force"]
        free_min, stop_min, force_excess = _force_margin(verified.get("force"), verified.get("position"), setup)
        excess = dict(stroke=_worst(verified.get("position"), lo_x, hi_x),
                      pressure=_worst(verified.get("pressure"), -np.inf, p_max),
                      force=force_excess if force_excess is not None else _worst(verified.get("force"), f_min, np.inf))
        out["verified"] = dict(
            position_range=_range(verified.get("position")), pressure_range=_range(verified.get("pressure")),
            force_range=_range(verified.get("force")), free_force_min=free_min, stop_force_min=stop_min, excess=excess,
            tolerance=dict(VERIFY_TOLERANCE),
            feasible=all(v is None or v <= VERIFY_TOLERANCE[k] for k, v in excess.items()))
        out["feasible"] = out["feasible"] and out["verified"]["feasible"]
    out["violations"] = _violations(out)
    return out


def _violations(report):
    """One line per violated limit, with what to change (empty when every limit holds)."""
    lines = []
    v = report.get("verified") or {}
    excess = v.get("excess", {})
    tol = v.get("tolerance", {})

    def over(kind, at_samples):
        return at_samples or (excess.get(kind) is not None and excess[kind] > tol.get(kind, 0.0))

    x, lim = report["position_range"], report["stroke_limits"]
    if lim is not None and over("stroke", x is not None and (x[0] < lim[0] - 1e-12 or x[1] > lim[1] + 1e-12)):
        xr = v.get("position_range") or x
        lines.append(f"stroke_margin: predicted {1e3 * xr[0]:.2f} … {1e3 * xr[1]:.2f} mm, limits {1e3 * lim[0]:.2f} "
                     f"… {1e3 * lim[1]:.2f} mm (the end stops less stroke_margin)")
    p, p_max = report["pressure_range"], report["max_pressure"]
    if p_max is not None and over("pressure", p is not None and p[1] > p_max + 1e-9):
        pr = v.get("pressure_range") or p
        lines.append(f"max_pressure: predicted up to {pr[1] / 1e5:.3f} bar abs, limit {p_max / 1e5:.3f} bar abs")
    f_min = report["min_force"]
    if f_min is not None:
        at_samples = _force_lines(report["free_force_min"], report["stop_force_min"], f_min)
        if over("force", bool(at_samples)):
            lines += _force_lines(v.get("free_force_min"), v.get("stop_force_min"), f_min) or at_samples
    if report["max_duty_step"] is not None and report["largest_duty_step"] > report["max_duty_step"] + 1e-9:
        lines.append(f"max_duty_step: a step of {report['largest_duty_step']:.3f}, limit {report['max_duty_step']:g}")
    return lines


@dataclasses.dataclass
class DesignResult:
    """The outcome of `design`.

    - `times` [s] (start of each PWM period), `duty` [-] (one value per period), `period` [s]; `signal()` gives the
      `Sampled` signal, `to_csv` writes it (`t [s]`, `duty [-]`).
    - `labels`, `values` (the design point), `subset` (the labels the criterion is on), `criterion` ("D" or "A").
    - `standard_errors`: predicted (Cramér-Rao) standard errors in physical units per label, for "design" (prior
      experiments + the designed one), "prior" (prior experiments alone; inf where they do not determine it) and
      "baseline" (prior + baseline experiments) and "target" (what `baseline_margin` asks of each parameter of
      `subset`; inf elsewhere) when a baseline was given; `baseline_shortfall` names those the design leaves short.
    - `objective`: [start, end] values of the criterion; `history`: per iteration [iteration, objective, criterion,
      step length, accepted].
    - `constraints`: the limits and what the design keeps of them: the duty band, the valve's switching thresholds,
      `duty_margin` and the duties they leave (`duty_limits`), the closest any period comes to a threshold
      (`threshold_distance`), the largest duty step; the predicted stroke, pressure and eq. 7 force extremes at the
      objective's samples and (`verified`) at the fit's resolution, against `stroke_limits`, `max_pressure`,
      `min_force`; `feasible` (every limit holds) and `violations` (one line per limit that does not).
    - `design_s`: wall time of the whole design; `compile_s`: of its start (compiling the objective and its
      gradient, overlapped with the prior and baseline experiments' Jacobians), before the first iteration.
    - `duration` [s]: of the run (the last period may end before its full length).
    - `prediction`: the predicted run at the objective's samples (t, position, pressure, eq. 7 force; not in JSON).
    - `payload_kg`: the payload [kg] of the designed run where `build` changed it from the model's (e.g.
      `pamjax.PayloadFromModel.advised(model)`), else None: the bench must carry it, and its recording be fitted
      with it (`payload_kg` in the run's meta.json entry or [[experiment]] table).
    - `points`: with a `spread`, one entry per design point (the model's first): its `values` (labels order), its
      `criterion`, `worst_violation` (of its limits, in the penalties' units; 0 when kept) and `standard_errors`
      ("design", and with a baseline "baseline" and "target", at that point), at the objective's resolution (250 Hz,
      4 substeps: within 0.2 % of the fit's); `objective` and `history` then hold the average criterion over them.
      None without a spread. `points_shortfall` names the parameters some point leaves short of its target.
    """

    times: list
    duty: list
    period: float
    labels: list
    values: list
    subset: list
    criterion: str
    standard_errors: dict
    objective: list
    history: list
    constraints: dict
    parametrisation: str
    iterations: int
    message: str
    design_s: float
    compile_s: float
    duration: float | None = None
    prediction: dict | None = dataclasses.field(default=None, repr=False, compare=False)
    payload_kg: float | None = None
    points: list | None = None

    def signal(self):
        """The designed duty as `pamjax.Sampled(times, duty, period=period)`."""
        return Sampled(jnp.asarray(self.times), jnp.asarray(self.duty), period=self.period)

    def to_dict(self):
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "prediction"}

    def to_json(self, path, overwrite=False):
        path = writable_path(path, overwrite)
        path.write_text(jsonio.dumps(self.to_dict(), indent=1))
        return path

    @property
    def feasible(self):
        """Whether the design keeps every limit (`constraints["violations"]` lists those it does not)."""
        return bool(self.constraints.get("feasible", True))

    @property
    def baseline_shortfall(self):
        """{label: the design's predicted standard error over its target} for each parameter the design leaves short
        of what `baseline_margin` asked (a goal the search pursues by a penalty, not a limit: the design stays valid);
        empty where every target is met or no baseline was given. At the fit's resolution where `verify`."""
        target = self.standard_errors.get("target")
        if target is None:
            return {}
        design = self.standard_errors["design"]
        return {lbl: d / t for lbl, d, t in zip(self.labels, design, target) if math.isfinite(t) and d > t * (1 + 1e-9)}

    @property
    def undetermined(self):
        """The parameters of `subset` whose predicted standard error is infinite: the design with the prior leaves
        them free (their information below 1e-9 of the largest, a direction the runs do not fix), so no standard
        error, target or ratio says anything about them. Typically a design point far from a plant (a fit that did
        not converge, a force law that leaves the muscle slack)."""
        design = self.standard_errors["design"]
        return [lbl for lbl, d in zip(self.labels, design) if lbl in self.subset and not math.isfinite(d)]

    @property
    def points_shortfall(self):
        """{label: the largest ratio over the design points of the predicted standard error to its target} for each
        parameter some design point leaves short of what `baseline_margin` asked there; empty without a spread, a
        baseline, or a shortfall."""
        worst = {}
        for point in self.points or []:
            errors = point["standard_errors"]
            for label, d, t in zip(self.labels, errors["design"], errors.get("target", [])):
                if math.isfinite(t) and d > t * (1 + 1e-9):
                    worst[label] = max(worst.get(label, 0.0), d / t)
        return worst

    def to_csv(self, path, overwrite=False, infeasible_ok=False):
        """`t [s],duty [-]`: one row per PWM period (its start and duty) and a last row at the run's end (the last
        duty again), so that a replay runs to the end; the predicted standard errors in '#' comment lines above
        (`pamjax.Recording.load(path)` reads the duty as channel "command", the bench's name for it;
        `Sampled(rec.t, rec["command"], period=...)` replays it; `pamjax.bench.load_bench` fits its recording as a
        "muscle_run"). A design
        that violates its limits is refused (a bench must not play it) unless `infeasible_ok`."""
        if not self.feasible and not infeasible_ok:
            raise PamjaxInputError("this design violates its limits (" + "; ".join(self.constraints["violations"])
                                   + "): a bench must not play it; pass infeasible_ok=True to write it anyway")
        path = writable_path(path, overwrite)
        lines = [f"# pamjax design: {self.criterion}-optimal over {', '.join(self.subset)}; PWM period "
                 f"{self.period} s; duty latched per period",
                 *([f"# payload {self.payload_kg:.6g} kg (not the model's): load the rig with it and fit the "
                    f"recording with payload_kg = {self.payload_kg:.6g}"] if self.payload_kg is not None else []),
                 "# predicted standard errors (Cramér-Rao, SI units): label, design"
                 + (", baseline" if "baseline" in self.standard_errors else "") + ", prior experiments alone"]
        for i, label in enumerate(self.labels):
            cols = [self.standard_errors["design"][i]]
            if "baseline" in self.standard_errors:
                cols.append(self.standard_errors["baseline"][i])
            cols.append(self.standard_errors["prior"][i])
            lines.append(f"#   {label}, " + ", ".join(f"{c:.6g}" for c in cols))
        lines.append("t [s],duty [-]")
        lines += [f"{t!r},{d!r}" for t, d in zip(map(float, self.times), map(float, self.duty))]
        end = self.times[-1] + self.period if self.duration is None else self.duration
        if float(end) > float(self.times[-1]):
            lines.append(f"{float(end)!r},{float(self.duty[-1])!r}")
        path.write_text("\n".join(lines) + "\n")
        return path

    def table(self):
        """Text table: label, value, predicted standard error (design, baseline, prior alone) and their ratio."""
        base = self.standard_errors.get("baseline")
        head = f"{'parameter':<40}{'value':>13}{'se design':>12}" + (f"{'se baseline':>13}{'ratio':>8}" if base
                                                                       else "") + f"{'se prior':>12}"
        rows = [head]
        for i, label in enumerate(self.labels):
            se = self.standard_errors["design"][i]
            row = f"{label:<40}{self.values[i]:>13.6g}{se:>12.3g}"
            if base:
                row += f"{base[i]:>13.3g}{base[i] / se:>8.2f}"
            rows.append(row + f"{self.standard_errors['prior'][i]:>12.3g}")
        return "\n".join(rows)

    def plot(self, path):
        """Figure: the duty, the predicted position and pressure with their limits, and the predicted relative
        standard errors (design, baseline, prior alone)."""
        from .design_plot import plot_design

        return plot_design(self, path)
