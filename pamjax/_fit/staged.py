"""Start values for a joint fit, found stage by stage from the experiments that determine each group of parameters.

A joint fit of every parameter from datasheet values is one large non-linear least-squares problem. On a bench with
tank tests and muscle runs, the muscle runs alone cannot separate the valve's flow scale from the muscle's volume, and
from the presets the first steps of a joint fit can trade the valve against the volume and the force law into a
region it never leaves: of six unseen plants drawn as the perturbed bench sets were (each fitted parameter × U(0.8,
1.2), `benchmarks/unseen_plants.py`), three ended at `max_steps` with residuals 60–120× the noise. An experimenter
would fit the valve on the tank tests first, where nothing else enters, then the muscle with that valve, then all
together. `staged_start` does that, deciding the stages from the structure of the experiments, not from names:

1. Experiments whose system lacks some free parameters (a tank test's system has the model's valve but no muscle
   or friction) fit the free parameters their systems do have, on those experiments alone.
2. The other free parameters are fitted on the remaining experiments (the whole system), the first stage's held.
3. The caller's joint fit of everything starts from the result (`fit(staged_start(...).model, ...)`), so that
   the final values, standard errors and status are those of the joint problem.

Where the experiments give no such split (every experiment sees every free parameter), nothing is done.
"""

import dataclasses

from .fit import fit
from .parameters import parameter_paths


@dataclasses.dataclass
class StagedStart:
    """`model`: the start model of the joint fit; `stages`: (name, free paths, experiment names, FitResult) per
    stage fitted."""

    model: object
    stages: list

    def summary(self):
        """One line per stage: what was fitted on what, and how the fit ended."""
        return [f"stage {name}: {len(res.labels)} parameters on {', '.join(exps)}: {res.status}, {res.iterations} "
                f"trial steps, cost {res.initial_cost:.4g} → {res.cost:.4g}" for name, _, exps, res in self.stages]


def _path(entry):
    """The parameter path of a `free` entry (a path string, or a dict with `path`), without an index."""
    path = entry if isinstance(entry, str) else entry.get("path") if isinstance(entry, dict) else None
    return None if path is None else path.split("[")[0]


def _seen(experiment, model, entries):
    """The entries of `free` whose parameter exists in the experiment's system (all of them where the experiment
    does not say how its system is built from the model)."""
    build = getattr(experiment, "build", None)
    if build is None:
        return list(entries)
    paths = parameter_paths(build(model))
    return [e for e in entries if _path(e) in paths]


def staged_start(model, experiments, free, *, max_steps=100, progress=None):
    """The start of a joint fit of `free` to `experiments`, stage by stage (see the module docstring).

    **Arguments:** as `pamjax.fit`'s; `max_steps` bounds each stage, `progress` is passed to each stage's fit.

    **Returns:** a `StagedStart` (`.model` to start the joint fit from; `.stages` with each stage's `FitResult`).
    """
    experiments, free = list(experiments), list(free)
    if any(_path(e) is None for e in free):  # an entry this cannot place: no stages, the joint fit as given
        return StagedStart(model, [])
    seen = [_seen(e, model, free) for e in experiments]
    partial = [i for i, s in enumerate(seen) if len(s) < len(free)]
    first = [e for e in free if any(e in seen[i] for i in partial)]
    if not partial or not first or len(first) == len(free):
        return StagedStart(model, [])
    stages = []
    exps = [experiments[i] for i in partial]
    res = fit(model, exps, first, max_steps=max_steps, progress=progress)
    stages.append(("1", [_path(e) for e in first], [e.name for e in exps], res))
    model = res.apply(model)
    rest = [e for e in free if e not in first]
    full = [experiments[i] for i in range(len(experiments)) if i not in partial]
    if full:
        res = fit(model, full, rest, max_steps=max_steps, progress=progress)
        stages.append(("2", [_path(e) for e in rest], [e.name for e in full], res))
        model = res.apply(model)
    return StagedStart(model, stages)
