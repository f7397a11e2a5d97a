"""The staged start of `pamjax fit` with a `[bench]` table, kept beside the fit's checkpoint (`staged_start.npz`).

A bench fit starts stage by stage (`pamjax.staged_start`: the valve on the tank tests, then the muscle on the runs,
each stage at most `[fit] max_steps`), and the joint fit's checkpoint fingerprints that start. When the joint fit ends
at `max_steps`, the command advises raising `max_steps` and resuming; before, `--resume` computed the staged start
again with the raised budget, and where a stage had itself stopped at `max_steps` (a rig whose payload rests on a
stop, stage 2 crawling at the stick-slip cost's kinks) the start came out different and the resume was refused ("the
start model differs in ..."), after a minute of stages redone. The start is now written when it is computed: the
free parameters' values exactly (float64), the problem it was computed for (the fingerprint of the config's model,
experiments and free parameters, `pamjax._files.fingerprint`) and the stages' summary; `--resume` starts the joint fit
from it, and computes nothing again.

Both files a fit keeps for `--resume` are read here: the staged start, and the summary of the checkpoint
(`checkpoint_summary`) that the command names before the fit (a damaged one refused by name) and when interrupted.
"""

import json

import numpy as np

from .._core.errors import PamjaxInputError
from .._files.fingerprint import UNREADABLE, differences, encode, fingerprint

STAGED_START = "staged_start.npz"



def checkpoint_summary(path, strict=False):
    """'iteration k (cost c)' of the checkpoint at `path`; None where there is none, or where it cannot be read
    (`strict`: a `PamjaxInputError` naming the file and what to do)."""
    if not path.is_file():
        return None
    try:
        with open(path, "rb") as file, np.load(file, allow_pickle=False) as f:  # closed also where np.load fails
            history = f["history"]
        return f"iteration {int(history[-1][0])} (cost {history[-1][1]:.6g})"
    except UNREADABLE as err:
        if not strict:
            return None
        raise PamjaxInputError(f"pamjax fit: {path} is not a readable checkpoint ({type(err).__name__}: {err}), so no "
                               "fit can be resumed from it: start again with --overwrite (which replaces it), or "
                               "choose another folder with --out") from None


def file_state(path):
    """What tells a rewritten file from the one found (`write_checkpoint` replaces it whole); None: no file."""
    try:
        stat = path.stat()
    except OSError:
        return None
    return stat.st_ino, stat.st_mtime_ns, stat.st_size


def save(folder, model, experiments, free, staged):
    """Write `staged` (a `pamjax.StagedStart` of `model`) into `folder` (an `OutputFolder`), atomically."""
    import pamjax as pj

    space = pj.ParameterSpace(staged.model, free)
    arrays = dict(values=np.asarray(space.initial_values(), dtype=np.float64),
                  problem=encode(fingerprint(model, experiments, free)),  # its model and free list order the values
                  summary=np.asarray(list(staged.summary()), dtype=str))
    folder.write(STAGED_START, lambda path: np.savez(path, **arrays))


def load(path, model, experiments, free):
    """The staged start kept in `path` for this problem: (start model, the stages' summary lines), or None where there
    is no such file (a checkpoint written before pamjax kept it: the start is then computed again). A file of another
    problem, or one that cannot be read, is a `PamjaxInputError` naming it."""
    import pamjax as pj

    if not path.is_file():
        return None
    try:
        with open(path, "rb") as file, np.load(file, allow_pickle=False) as f:  # closed also where np.load fails
            values, summary = f["values"], [str(s) for s in f["summary"]]
            saved = json.loads(str(f["problem"]))
    except UNREADABLE as err:
        raise PamjaxInputError(f"resume: {path} is not a readable staged start ({type(err).__name__}: {err}); start "
                               "again with --overwrite") from None
    diff = differences(saved, fingerprint(model, experiments, free))
    if diff:
        raise PamjaxInputError(f"resume: {path} holds the staged start of a different fit: " + "; ".join(diff)
                               + ". Resume with the same config and data, or start again with --overwrite")
    return pj.ParameterSpace(model, free).with_values(values), summary
