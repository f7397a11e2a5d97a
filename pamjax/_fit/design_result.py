"""`DesignResult`: what `pamjax.design` returns (the signal, predicted standard errors, constraints), with its CSV,
JSON, table and figure."""

import dataclasses
import json

import jax.numpy as jnp

from .._physics.signals import Sampled
from .recording import _writable


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
    - `constraints`: the predicted stroke and pressure extremes, the largest duty step, the limits, `feasible`.
    - `design_s`: wall time of the whole design; `compile_s`: of its start (compiling the objective and its
      gradient, overlapped with the prior and baseline experiments' Jacobians), before the first iteration.
    - `prediction`: the predicted run at the objective's samples (t, position, pressure; not in JSON).
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

    def to_csv(self, path, overwrite=False):
        """`t [s],duty [-]`, one row per PWM period, the predicted standard errors in '#' comment lines above
        (`pamjax.Recording.load(path)` reads it; `Sampled(rec.t, rec["duty"], period=...)` replays it)."""
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
