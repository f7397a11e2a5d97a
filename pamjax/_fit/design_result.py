"""`DesignResult`: what `pamjax.design` returns (the signal, predicted standard errors, constraints), with its CSV,
JSON, table and figure."""

import dataclasses
import json

import jax.numpy as jnp

from .._core.errors import PamjaxInputError
from .._physics.signals import Sampled
from .recording import _writable


class PamjaxDesignWarning(UserWarning):
    """A design that ends outside its limits (`DesignResult.constraints["violations"]` says which)."""


@dataclasses.dataclass
class DesignResult:
    """The outcome of `design`.

    - `times` [s] (start of each PWM period), `duty` [-] (one value per period), `period` [s]; `signal()` gives the
      `Sampled` signal, `to_csv` writes it (`t [s]`, `duty [-]`).
    - `labels`, `values` (the design point), `subset` (the labels the criterion is on), `criterion` ("D" or "A").
    - `standard_errors`: predicted (Cramér-Rao) standard errors in physical units per label, for "design" (prior
      experiments + the designed one), "prior" (prior experiments alone; inf where they do not determine it) and
      "baseline" (prior + baseline experiments) when a baseline was given.
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
    duration: float = None
    prediction: dict = dataclasses.field(default=None, repr=False, compare=False)

    def signal(self):
        """The designed duty as `pamjax.Sampled(times, duty, period=period)`."""
        return Sampled(jnp.asarray(self.times), jnp.asarray(self.duty), period=self.period)

    def to_dict(self):
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "prediction"}

    def to_json(self, path, overwrite=False):
        path = _writable(path, overwrite)
        path.write_text(json.dumps(self.to_dict(), indent=1))
        return path

    @property
    def feasible(self):
        """Whether the design keeps every limit (`constraints["violations"]` lists those it does not)."""
        return bool(self.constraints.get("feasible", True))

    def to_csv(self, path, overwrite=False, infeasible_ok=False):
        """`t [s],duty [-]`: one row per PWM period (its start and duty) and a last row at the run's end (the last
        duty again), so that a replay runs to the end; the predicted standard errors in '#' comment lines above
        (`pamjax.Recording.load(path)` reads the duty as channel "command", the bench's name for it;
        `Sampled(rec.t, rec["command"], period=...)` replays it; `pamjax.load_bench` fits its recording as a
        "muscle_run"). A design
        that violates its limits is refused (a bench must not play it) unless `infeasible_ok`."""
        if not self.feasible and not infeasible_ok:
            raise PamjaxInputError("this design violates its limits (" + "; ".join(self.constraints["violations"])
                                   + "): a bench must not play it; pass infeasible_ok=True to write it anyway")
        path = _writable(path, overwrite)
        lines = [f"# pamjax design: {self.criterion}-optimal over {', '.join(self.subset)}; PWM period "
                 f"{self.period} s; duty latched per period",
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
