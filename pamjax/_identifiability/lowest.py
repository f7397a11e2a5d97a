"""`profile_to_minimum`: profile a fit's parameters, and where a profile finds a lower cost than the fit's, fit again
from the lowest re-fitted point and profile again.

A profile re-fits every other parameter with one held at values stepping away from the fit
(`pamjax.profile_likelihood`). Where one of those points lies below the fit's cost, the fit had stopped short of the
lowest minimum along that parameter (a kink of a stick-slip cost, a valley the damped steps did not follow): the
verdicts of that profile say nothing, and the point itself is a better start. This takes it: fit from it
(`ProfileResult.lower_start`), profile the new fit, at most `rounds` profiles in all. What it cannot do is reach a
minimum in another valley that no profile enters: on a muscle run whose payload rests on a stroke limit most of the
time, minima about as low can lie far apart (docs/fitting.md, "Runs that hold the payload on a stop").
"""

import dataclasses
from collections.abc import Sequence
from typing import Any

from .._core.errors import PamjaxInputError
from .._fit.fit import FitResult, Progress, fit
from .profile import PROFILED_STATUSES, ProfileResult, profile_likelihood

ROUNDS = 3  # profiles at most: the first, and two more after refits from a lower point


@dataclasses.dataclass
class ProfiledFit:
    """What `profile_to_minimum` ends with: `result` (the last fit: the given one, or a refit from a lower point),
    `profile` (its profile; its `warnings` say where a lower point remains, if the rounds ran out), `refits` (one dict
    per refit: the profile's time and Δχ² that led to it, the cost before and after, its status, steps and time) and
    `profile_s` (all profiles' seconds)."""

    result: FitResult
    profile: ProfileResult
    refits: list
    profile_s: float


def profile_to_minimum(
    result: FitResult,
    names: str | Sequence[str] | None = None,
    *,
    rounds: int = ROUNDS,
    max_steps: int = 100,
    progress: bool = True,
    fit_progress: Progress = None,
    **profile_options: Any,
) -> ProfiledFit:
    """Profile `names` of the fit `result` (`pamjax.profile_likelihood`; default every fitted parameter); where a
    re-fitted point lies below the fit's cost, fit again from the lowest one (`pamjax.fit` with the result's
    experiments and free parameters, at most `max_steps` steps) and profile the new fit, at most `rounds` profiles.
    A refit that does not end lower, or not at a minimum (status other than 'converged' / 'at bound'), ends the
    rounds (kept where its cost is lower). `profile_options` go to every profile (`level`, `max_points`, `span`,
    `workers`, ...); `progress` is theirs and this function's lines, `fit_progress` the refits' (`pamjax.fit`'s
    `progress`; default: `progress`). Returns a `ProfiledFit`."""
    if not (isinstance(rounds, int) and rounds >= 1):
        raise PamjaxInputError(f"rounds must be an int >= 1, got {rounds!r}")
    refits, seconds = [], 0.0
    while True:
        prof = profile_likelihood(result, names, progress=progress, **profile_options)
        seconds += prof.profile_s
        lower = prof.lowest()
        if lower is None or len(refits) == rounds - 1:
            return ProfiledFit(result, prof, refits, seconds)
        if progress:
            print(f"  the profile found a cost lower than the fit's by Δχ² = {-lower[0]:.3g}: fitting again from "
                  "there", flush=True)
        steps = progress if fit_progress is None else fit_progress
        new = fit(prof.lower_start(result), result.experiments, result.paths, max_steps=max_steps, progress=steps,
                  warn=False)  # its warnings are in its result, as the first fit's
        refits.append(dict(profile_s=prof.profile_s, delta_chi2=lower[0], from_cost=prof.cost, cost=new.cost,
                           status=new.status, iterations=new.iterations, fit_s=new.fit_s))
        lower_cost = new.cost < prof.cost  # the profile's cost at the fit: that of the model the result carries
        if not lower_cost or new.status not in PROFILED_STATUSES:
            if progress:
                print(f"  the refit ended with status {new.status}, cost {new.cost:.6g} (the fit's {prof.cost:.6g}):"
                      f" {'kept' if lower_cost else 'not kept'}, not profiled", flush=True)
            return ProfiledFit(new if lower_cost else result, prof, refits, seconds)
        result = new
