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

A parameter `Measurement` (a calibrated gain with its uncertainty) does not decide the stages; it is fitted in every
stage that frees its parameter, and in the joint problem.

A rig's position-sensor offset (`sensors[...].position_offset`) is held at its start value through the stages and
fitted in the joint problem only. A shift of the position origin is absorbed by the force and volume laws' polynomials
in x; only a run resting on a stroke limit fixes it, and from the presets' plant the model's payload does not rest
there yet, so in stage 2 the offset is a near-null direction that the fit wanders along: on an unseen rig
(benchmarks/RESULTS.md, identify: rig402) stage 2 moved it to −9.3 mm for a true +0.06 mm and ended at 18× the
final cost, and the joint fit took 67 steps (80 s) to come back; held through the stages, stage 2 ended in the
right basin and the joint fit took 9 steps to the same optimum (same cost, same offset).

A stage that ends at a probed minimum (`pamjax.LevenbergMarquardt`: no single-parameter move lowers the cost, at a
point where the cost is not smooth, e.g. where a stick-slip phase begins or ends as a parameter moves) hands the next
fit its values moved `KINK_SHIFT` (0.01) marginal standard errors off that point: the derivative there is one-sided,
and the joint fit's first Jacobian, taken exactly there, misleads it. On perturbed4 (benchmarks/RESULTS.md,
identify) stage 2 ended so, and the joint fit from its point crawled for 100 steps (0.6 of the cost gained, status
max_steps); moved 0.01 (or ±0.05) standard errors, or 1e-4 of each value at random, it converged in 10 steps, each
to the same cost, 7.8 lower. The move is in marginal standard errors, all one way, which along the correlated
force-law coefficients raises the cost by tens to thousands (a step the joint fit takes back at once); 0.01 of the
conditional ones (the probes' unit: the cost hardly moves) left the joint fit crawling as before: the point must
leave the kink's neighbourhood, not only the kink.

Three problems compile instead of one. The programs of stage 2 and of the joint problem (the largest: every
experiment, a tangent per free parameter) do not depend on the values stage 1 finds, so they are compiled in a
second thread from the start (`precompile`: XLA compiles outside Python's lock, on the second core where there is
one) while stage 1 compiles and fits, then stage 2 fits; a stage that would start before its programs are ready
waits for them rather than compiling them a second time, and the joint fit after `staged_start` compiles nothing.
The waits are reported as `waited_s` (compilation on the critical path, beside each stage's own `compile_s`).
"""

import dataclasses
import threading
import time
from collections.abc import Sequence

import equinox as eqx
import numpy as np

from .experiment import AbstractExperiment
from .fit import FitResult, Progress, check_fit_inputs, fit, precompile, start_cost
from .force_balance import force_balance
from .measurement import is_measurement
from .parameters import Free, ParameterSpace, join_path, split_path
from .problem import breaks_a_check
from .solver import PROBED_MINIMUM

# Marginal standard errors by which a stage's values are moved off the point where it ended when that was a probed
# minimum (module docstring): small beside the joint fit's own moves (perturbed4's moved b12 and b23 by 2-3 of them).
KINK_SHIFT = 0.01


@dataclasses.dataclass
class StagedStart:
    """`model`: the start model of the joint fit; `stages`: (name, free paths, experiment names, FitResult) per
    stage fitted; `waited_s`: wall time the stages and the end spent waiting for the programs compiled in the second
    thread (stage 2's, the joint problem's); `precompile_s`: that thread's wall time (0 when not used); `balance`: stage
    2's start from the muscle runs' force balance (`_balanced_start`), None where it did not apply; `fit_s` and
    `compile_s`: the stages' times."""

    model: eqx.Module
    stages: list[tuple[str, list[str], list[str], FitResult]]
    waited_s: float = 0.0
    precompile_s: float = 0.0
    balance: dict | None = None

    @property
    def fit_s(self):
        """The stages' fit time, and the force balance's (its small program compiled, and stage 2's cost evaluated
        from both starts)."""
        return sum(res.fit_s for *_, res in self.stages) + (self.balance["seconds"] if self.balance else 0.0)

    @property
    def compile_s(self):
        """Compilation on the critical path: the stages' own, and the waits for the second thread's."""
        return sum(res.compile_s for *_, res in self.stages) + self.waited_s

    def summary(self):
        """One line per stage: what was fitted on what, and how the fit ended."""
        kink = f" (at a probed minimum: handed on {KINK_SHIFT} marginal standard errors off it)"
        lines = [f"stage {name}: {len(res.labels)} parameters on {', '.join(exps)}: {res.status}, {res.iterations} "
                 f"trial steps, cost {res.initial_cost:.4g} → {res.cost:.4g}"
                 f"{kink if res.message == PROBED_MINIMUM else ''}" for name, _, exps, res in self.stages]
        if self.balance is not None:
            b = self.balance
            lines.insert(1, f"stage 2's start: the muscle runs' force balance ({b['samples'][0]} sliding samples, "
                            f"{b['samples'][1]} at rest, {b['samples'][2] + b['samples'][3]} on a stroke limit) gives "
                            f"stage 2 a cost of {b['stage_cost'][1]:.4g} against {b['stage_cost'][0]:.4g} from stage "
                            f"1's model: {'started from it' if b['used'] else 'not used'}")
        if self.precompile_s:
            lines.append(f"stage 2's and the joint problem's programs compiled beside stage 1 in a second thread "
                         f"({self.precompile_s:.1f} s; {self.waited_s:.1f} s waited for)")
        return lines


def _entry(entry):
    """A `free` entry's path as given, array index and all (a stage's list read ['valve.coefficients',
    'valve.coefficients'] for [1,0] and [1,1]: `_path` strips the index, for grouping)."""
    return entry if isinstance(entry, str) else entry.get("path")


def _path(entry):
    """The parameter path of a `free` entry (a path string, or a dict with `path`), without an array index."""
    path = entry if isinstance(entry, str) else entry.get("path") if isinstance(entry, dict) else None
    if path is None:
        return None
    steps, _ = split_path(path)
    return join_path(steps)


def _seen(experiment, model, entries):
    """The entries of `free` whose parameter this experiment's predictions depend on (`AbstractExperiment.sees`; all
    of them where the experiment does not say)."""
    paths = experiment.sees(model)
    if paths is None:
        return list(entries)
    return [e for e in entries if _path(e) in paths]


def _is_plant(entry):
    from .rig import is_nuisance

    return not is_nuisance(_path(entry))


def _joint_only(entry):
    """A rig's position-sensor offset: held through the stages, fitted in the joint problem (module docstring)."""
    steps, _ = split_path(_path(entry))
    return len(steps) == 3 and steps[0] == "sensors" and steps[2] == "position_offset"


def _measuring(measures, model, entries):
    """The measurements of parameters among the `free` entries `entries`."""
    paths = {_path(e) for e in entries}
    return [m for m in measures if m.sees(model) <= paths]


class _Background:
    """`precompile` of several problems, in order, in one daemon thread; `wait(i)` blocks until problem i is
    compiled and returns the seconds waited. An error ends the thread without being raised here: the fit of that
    problem then compiles it itself and raises it where it belongs."""

    def __init__(self, problems):
        self.seconds = 0.0
        self.done = [threading.Event() for _ in problems]
        self.cancelled = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(problems,), daemon=True)
        self.thread.start()

    def _run(self, problems):
        try:
            for (model, experiments, free), done in zip(problems, self.done):
                if self.cancelled.is_set():
                    break
                self.seconds += precompile(model, experiments, free)
                done.set()
        except Exception:  # noqa: BLE001, S110 - raised again by the fit that compiles the problem itself
            pass
        finally:
            for done in self.done:
                done.set()

    def wait(self, i):
        t0 = time.perf_counter()
        self.done[i].wait()
        return time.perf_counter() - t0

    def stop(self):
        """After an error or Ctrl-C in a stage: compile nothing more, and wait for the compilation under way (XLA
        compiling in a thread while the interpreter shuts down crashes the process: exit 139 or 134)."""
        self.cancelled.set()
        self.thread.join()


def staged_start(model: eqx.Module, experiments: Sequence[AbstractExperiment], free: Free, *, max_steps: int = 100,
                 progress: Progress = None, background_compile: bool = True) -> StagedStart:
    """The start of a joint fit of `free` to `experiments`, stage by stage (see the module docstring).

    **Arguments:** as `pamjax.fit`'s; `max_steps` bounds each stage, `progress` is passed to each stage's fit;
    `background_compile`: compile stage 2's and the joint problem's programs in a second thread from the start
    (default); False compiles each stage's programs when it starts and leaves the joint problem's to the joint fit.

    **Returns:** a `StagedStart` (`.model` to start the joint fit from; `.stages` with each stage's `FitResult`,
    whose `warnings` are not emitted as Python warnings: the joint fit from it emits its own).
    """
    joint_free = free if isinstance(free, str) else list(free)  # a string: refused below as fit refuses it
    if not isinstance(free, str) and any(_path(e) is None for e in joint_free):  # an entry this cannot place: no
        return StagedStart(model, [])  # stages, the joint fit as given
    # Refused before any stage compiles, as the joint fit refuses them (a misspelt path would drop out of the stages,
    # two experiments of one name or a parameter freed twice fail only in the stage that fits them)
    experiments, _ = check_fit_inputs(model, experiments, joint_free, max_steps)
    free = [e for e in joint_free if not _joint_only(e)]  # what the stages fit
    # A parameter `Measurement` does not decide the stages (it sees one parameter, not a part of the plant): each
    # stage fits it beside the recordings where it frees the measured parameter
    joint = experiments  # the joint problem's, in the caller's order (its programs are compiled for that fit)
    measures = [e for e in experiments if is_measurement(e)]
    experiments = [e for e in experiments if not is_measurement(e)]
    seen = [_seen(e, model, free) for e in experiments]
    # Stage 1's experiments see part of the plant (a tank test: the valve, no muscle); a rig's nuisances (each run's
    # own conditions, the sensors) do not decide the stages: every experiment sees only its own run's.
    plant = [e for e in free if _is_plant(e)]
    partial = [i for i, s in enumerate(seen) if len([e for e in s if _is_plant(e)]) < len(plant)]
    first = [e for e in free if any(e in seen[i] for i in partial)]
    if not partial or not first or len(first) == len(free) or all(not _is_plant(e) for e in first):
        return StagedStart(model, [])
    stages = []
    rest = [e for e in free if e not in first]
    exps1 = [experiments[i] for i in partial] + _measuring(measures, model, first)
    full = [experiments[i] for i in range(len(experiments)) if i not in partial]
    full = full + _measuring(measures, model, rest) if full else full
    # Stage 2's programs, then the joint problem's, compile in a second thread while stage 1 fits (their structure
    # does not depend on the values stage 1 finds); each fit waits for its programs rather than compiling them twice.
    background = _Background(([(model, full, rest)] if full else []) + [(model, joint, joint_free)]) \
        if background_compile else None
    waited, balance = 0.0, None
    try:
        res = fit(model, exps1, first, max_steps=max_steps, progress=progress, warn=False)
        stages.append(("1", [_entry(e) for e in first], [e.name for e in exps1], res))
        model = _off_a_kink(res.apply(model), res, first)
        if full:
            waited += background.wait(0) if background is not None else 0.0
            model, balance = _balanced_start(model, full, rest)
            res = fit(model, full, rest, max_steps=max_steps, progress=progress, warn=False)
            stages.append(("2", [_entry(e) for e in rest], [e.name for e in full], res))
            model = _off_a_kink(res.apply(model), res, rest)
        waited += background.wait(-1) if background is not None else 0.0
    except BaseException:  # an error or Ctrl-C in a stage: the second thread ends before the error leaves here
        if background is not None:
            background.stop()
        raise
    return StagedStart(model, stages, waited_s=waited,
                       precompile_s=background.seconds if background is not None else 0.0, balance=balance)


def _off_a_kink(model, res, free):
    """A stage's result moved `KINK_SHIFT` marginal standard errors off the point where it ended (each parameter up,
    those of infinite standard error not at all), if that was a probed minimum (module docstring); else the result
    as it is."""
    if res.message != PROBED_MINIMUM:
        return model
    space = ParameterSpace(model, free)
    se = np.asarray(res.standard_errors, dtype=float)
    moved = np.asarray(space.initial_values(), dtype=float) + KINK_SHIFT * np.where(np.isfinite(se), se, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):  # a move past a bound: θ not finite
        if not np.all(np.isfinite(np.asarray(space.theta(moved)))):
            return model
    moved = space.with_values(moved, model)
    return model if bool(breaks_a_check(moved)) else moved  # nor past a check that ties parameters together


def _balanced_start(model, experiments, free):
    """Stage 2's start: the muscle runs' force balance (`force_balance`: the force law moved to where the recorded
    payload is, without a solve) where stage 2's cost is lower there than at the stage-1 model, else that model.
    Returns (start model, `StagedStart.balance`: the balance's `info`, stage 2's cost from each start (`stage_cost`),
    whether the balance's was `used`, and the wall time of all this, `seconds`)."""
    t0 = time.perf_counter()
    balanced = force_balance(model, experiments, free)
    if balanced is None:
        return model, None
    before, after = start_cost(model, experiments, free), start_cost(balanced[0], experiments, free)
    info = dict(balanced[1], stage_cost=(before, after), used=bool(after < before), seconds=time.perf_counter() - t0)
    return (balanced[0] if after < before else model), info
