"""A fit's checkpoint: the iteration state after every iteration, as one `.npz` file written atomically, with the
fingerprint of the problem it belongs to (`pamjax._files.fingerprint`), so that `fit(..., resume=path)` continues
exactly where the interrupted fit stopped, and refuses a checkpoint of another problem.

The arrays are the solver's (`pamjax._fit.drive.state_arrays`: θ, the solver's state, the history); this module
checks and stores them, the fit turns them back into its solver's state (`drive.state_from_arrays`)."""

import contextlib
import os
import pathlib

import numpy as np

from .._core.errors import PamjaxInputError
from .fingerprint import encode

CHECKPOINT_FORMAT = 3  # 3: pamjax's optimistix solver's state (`solver.state_arrays`); 2 (the host
READABLE_FORMATS = (2, 3)  # Levenberg-Marquardt's, until 2026-11) resumes in it, at the same point


def check_checkpoint_path(checkpoint, resume, overwrite):
    """Before any fit: `checkpoint` may only replace an existing file if asked to, or if it is the file resumed."""
    if checkpoint is None:
        return
    path = pathlib.Path(checkpoint)
    if path.suffix != ".npz":
        raise PamjaxInputError(f"checkpoint must be an .npz path, got {str(checkpoint)!r}")
    same = resume is not None and path.resolve() == pathlib.Path(resume).resolve()
    if path.exists() and not (overwrite or same):
        raise FileExistsError(f"checkpoint {path} exists; pass overwrite=True to replace it (or resume from it)")


def write_checkpoint(path, labels, arrays, fingerprint=None):
    """Save the iteration state (`arrays`: θ, the solver's state, the history; every array exactly) after an
    iteration. Written to a temporary file of this process's own (two writers never share one) and renamed, so an
    interruption or a failed write leaves the previous checkpoint whole; the temporary file is removed on any
    failure. A write that fails (a full disk: the fit stopped with a bare "[Errno 28] No space left on device" and
    left `checkpoint.npz.tmp.npz` behind) is an `OSError` of the same errno naming the checkpoint (`filename`) and
    what is kept."""
    path = pathlib.Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}.npz")  # ends in .npz: np.savez adds none
    extra = {} if fingerprint is None else {"fingerprint": encode(fingerprint)}  # see pamjax._files.fingerprint
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(tmp, format=CHECKPOINT_FORMAT, labels=np.asarray(labels, dtype=str), **arrays, **extra)
        os.replace(tmp, path)
    except BaseException as err:  # a Ctrl-C during the write too: no half-written file left behind
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        if not isinstance(err, OSError):
            raise
        kept = ("the checkpoint already there (the last one written) is kept whole: make room (or fix the folder) "
                "and resume the fit from it (pamjax fit --resume, or pamjax.fit(..., resume=...))"
                if path.is_file() else "no earlier checkpoint is there to resume from")
        raise OSError(err.errno, f"could not write the fit's checkpoint {path} ({err.strerror or err}); {kept}",
                      str(path)) from err


def read_checkpoint(path, labels, num_residuals):
    """The arrays of a checkpoint of this fit (its parameters `labels`, `num_residuals` residuals), checked: a
    `PamjaxInputError` for a missing file, another format, other parameters or another number of residuals."""
    path = pathlib.Path(path)
    if not path.exists():
        raise PamjaxInputError(f"resume: checkpoint {path} does not exist")
    with np.load(path) as f:
        data = {k: f[k] for k in f.files}
    if int(data.get("format", -1)) not in READABLE_FORMATS:
        raise PamjaxInputError(f"resume: {path} is not a pamjax fit checkpoint (format {CHECKPOINT_FORMAT})")
    if list(data["labels"]) != list(labels):
        raise PamjaxInputError(f"resume: {path} was saved for parameters {list(data['labels'])}, not {list(labels)}")
    if np.shape(data["residual"]) != (num_residuals,):
        raise PamjaxInputError(f"resume: {path} holds {np.size(data['residual'])} residuals, this fit has "
                               f"{num_residuals} (other experiments or data)")
    return data
