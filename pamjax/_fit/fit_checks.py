"""What `fit` refuses before anything is set up or compiled: float64, the experiments, the step budget, the default
solver's settings, the free entries and the measurements' parameters, and the paths it will write (`out`,
`checkpoint`). `staged_start` and `multistart` run the same checks first (`check_fit_inputs`)."""

import os
import pathlib
from collections.abc import Iterator, Mapping

from .._core.errors import PamjaxInputError, check_count, require_float64
from .._files.checkpoint import check_checkpoint_path
from .._systems.base import AbstractSystem
from .experiment import AbstractExperiment
from .measurement import check_measured_free
from .parameters import ParameterSpace
from .recording import Recording


def check_settings(ftol, xtol, gtol, stall_steps):
    """The default solver's settings, checked before anything is set up (as `LevenbergMarquardt` checks them);
    returns `stall_steps` as an int (a NumPy integer too)."""
    check_count(stall_steps, "stall_steps")
    for label, tol in (("ftol", ftol), ("xtol", xtol), ("gtol", gtol)):
        if isinstance(tol, bool) or not (isinstance(tol, (int, float)) and 0 <= tol < 1):
            raise PamjaxInputError(f"{label} must be a number in [0, 1), got {tol!r}")
    return int(stall_steps)


def check_output_path(path, name):
    """A file `fit` writes (`out`, `checkpoint`) can be written where it is asked for: not a folder, and the nearest
    folder of it that exists (the others are made) a writable folder, not a file. Checked before the fit: these
    failed as raw `IsADirectoryError` / `FileExistsError` after the whole fit (or its first iteration), its result
    lost."""
    path = pathlib.Path(path)
    if path.is_dir():
        raise PamjaxInputError(f"{name} {str(path)!r} is a folder: give the path of a file in it "
                               f"({name}={str(path / ('fit.json' if name == 'out' else 'fit.npz'))!r})")
    folder = next((p for p in path.parents if p.exists()), pathlib.Path("."))
    if not folder.is_dir():
        raise PamjaxInputError(f"{name} {str(path)!r} lies under {str(folder)!r}, which is a file, not a folder: "
                               "give a path in a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PamjaxInputError(f"{name} {str(path)!r}: the folder {str(folder)!r} is not writable")


def check_experiments(experiments, model=None):
    """The `experiments` argument of `fit`, `evaluate` and `predictions`: one pamjax experiment or a list (tuple) of
    them, at least one, their names unique; returned as a list. `evaluate` and `predictions` took anything: an empty
    list returned nothing (or ended in NumPy's "need at least one array to concatenate"), a dict, a recording or the
    arguments swapped (`evaluate(experiment, model)`) in raw AttributeErrors. `model`, where given, must be no
    experiment."""
    kinds = "pamjax experiments (Experiment, ForceMapExperiment, ...)"
    if isinstance(model, AbstractExperiment):
        raise PamjaxInputError(f"model must be the model whose predictions are compared (a system, e.g. "
                               f"presets.mas10_system()), got the {type(model).__name__} {model.name!r}: the "
                               "arguments are (model, experiments)")
    if isinstance(experiments, AbstractExperiment):
        experiments = [experiments]
    elif isinstance(experiments, Mapping):
        raise PamjaxInputError(f"experiments must be a list of {kinds}, got a {type(experiments).__name__}: pass "
                               "list(experiments.values()) (each experiment carries its own name)")
    elif not isinstance(experiments, (list, tuple)):
        raise PamjaxInputError(f"experiments must be {kinds}: one, or a list of them; got "
                               f"{type(experiments).__name__}{_what_it_is(experiments)}")
    experiments = list(experiments)
    if not experiments:
        raise PamjaxInputError("experiments must be a non-empty list")
    for e in experiments:
        if not isinstance(e, AbstractExperiment):
            raise PamjaxInputError(f"experiments must be {kinds}, got {type(e).__name__}{_what_it_is(e)}")
    names = [e.name for e in experiments]
    if len(set(names)) != len(names):
        raise PamjaxInputError(f"experiment names must be unique, got {names}")
    return experiments


def _what_it_is(x):
    """What to write instead of `x`, given as an experiment: a recording, a model (the arguments swapped), an
    iterator."""
    if isinstance(x, Recording):
        return ": a recording is compared through an experiment, pj.Experiment(recording, signal, channels=[...])"
    if isinstance(x, AbstractSystem):
        return ", a model: the arguments are (model, experiments)"
    if isinstance(x, Iterator):
        return ": pass a list (list(...))"
    return ""


def validate_fit(experiments, max_steps, out, overwrite, checkpoint, resume):
    """`fit`'s arguments besides the model and the free entries, checked; returns the experiments as a list."""
    require_float64("pamjax.fit")
    if out is not None:
        check_output_path(out, "out")
        if pathlib.Path(out).exists() and not overwrite:
            raise FileExistsError(f"{out} exists; pass overwrite=True to replace it")
    check_checkpoint_path(checkpoint, resume, overwrite)
    if checkpoint is not None:
        check_output_path(checkpoint, "checkpoint")
    experiments = check_experiments(experiments)
    check_count(max_steps, "max_steps")
    return experiments


def check_free(model, experiments, free):
    """The `ParameterSpace` of `free` (every entry checked), and the measurements' parameters freed."""
    space = ParameterSpace(model, free)
    check_measured_free(model, experiments, free)
    _refuse_free_pwm_frequency(model, experiments, space)
    return space


def _refuse_free_pwm_frequency(model, experiments, space):
    """A free PWM frequency with an experiment on the PWM-synchronous grid is refused: `fit` sizes that grid (its
    number of periods, a static size) once, at the start model, so at a trial frequency above the start the periods
    end before the recording does and its last samples were extrapolated: noise-free MAS-10 stick-slip data at
    50.5 Hz fitted from 50 Hz gave 50.4974 Hz at a cost of 446 (not ~0)."""
    frequencies = [label for label in space.labels if label.split(".")[-1] == "pwm_frequency"]
    if not frequencies:
        return
    for e in experiments:
        bound = e.bind(model)  # a sized copy where the experiment has a fixed grid
        if bound is not e and bound.system_for(model).valve.switches:
            raise PamjaxInputError(
                f"free {frequencies[0]!r}: experiment {e.name!r} is solved on the PWM-synchronous grid, whose number "
                "of periods is sized once at the start model, so a trial frequency above the start leaves the end of "
                "the recording uncovered; fix pwm_frequency (fit the others), or fit it with a smoothed valve "
                "(OnOffValve(mode='smooth')) and the experiment's stepping='adaptive' on a plant without stick-slip "
                "friction")


def check_fit_inputs(model, experiments, free, max_steps=100):
    """What `fit(model, experiments, free, max_steps=max_steps)` refuses before anything is set up or compiled, by
    the same checks: float64, the experiments (pamjax experiments, at least one, unique names), the step budget, the
    free entries and the measurements' parameters. Returns (the experiments as a list, the `ParameterSpace`).
    `staged_start` calls it first: its stages never fit a part of a problem the joint fit would refuse."""
    experiments = validate_fit(experiments, max_steps, None, False, None, None)
    return experiments, check_free(model, experiments, free)

