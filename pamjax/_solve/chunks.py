"""Long fixed-grid runs solved in pieces, so that their memory stays bounded.

A fixed-grid solve (`stepping="pwm"` or `"grid"`, the default of stick-slip systems) keeps every step's end states
and slopes until its outputs are interpolated at the output times: about half a kilobyte per step, so a 19,000 s
run of the fitted stick-slip model (19 M steps of 1 ms) took 9.3 GB. `plan` cuts such a run at output times that are
nodes of its own grid into pieces of at most `PIECE_STEPS` steps; each piece is solved from the state its
predecessor ended in, on the same grid, so the pieces join into the run a single solve gives (the same nodes up to
rounding; a test compares them). The cut points are:

- `"grid"`: output times on the uniform grid t0 + k h of the whole run (the piece is solved with that h);
- `"pwm"`: PWM period starts at which the valve is closed in the whole run (the grid assumes a closed valve before
  its first period; `pamjax._solve.synchronous.open_at_start`).

All pieces span one number of rows (one compiled program); where that needs it, the last piece starts earlier and
overlaps its predecessor, whose rows are kept (the overlap's steps count twice in `num_steps`).

A run with no such output times (times off the grid, a valve held open for ever) is solved whole, unless its
estimated memory exceeds what the machine has available: then `plan` refuses it, with the estimate and what to
change.
"""

import math
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from .._core.errors import PamjaxInputError
from . import synchronous as _sync
from .grid import MAX_EVENTS

# Steps per piece: ~2.6e5 steps of a stick-slip system (3 event slots of 4 states) take ~150 MB; fewer pieces would
# save little time (each is one compiled loop; pieces of one size share their program), more would cost compilations.
PIECE_STEPS = 2**18
_NODE_TOL = 1e-6  # of a step: how near an output time must lie to a grid node to be one (rounding only)


def bytes_per_step(system, state_size):
    """Memory [B] a fixed-grid solve keeps per step until its outputs are interpolated: per event slot the segment's
    start, length, two end states and two slopes (`pamjax._solve.grid.integrate`), plus the interval's own arrays."""
    slots = MAX_EVENTS + 1 if system.hybrid else 1
    return 8 * (slots * (2 + 4 * state_size) + 8)


def _steps(stepping, size, substeps):
    return size * (substeps + 2) if stepping == "pwm" else size


def plan(system, signal, ts, t0, stepping, substeps, grid_step, size):
    """The pieces of a fixed-grid run over the output times `ts` (host array) from `t0`: a list of (first row, last
    row, grid_step of the piece), or None to solve it whole (see the module docstring). `size`: the whole run's
    static size (periods or steps). Every piece spans the same number of rows from a cut point, so that the pieces
    share one compiled program: a piece starts at the last cut point its predecessor reaches (they overlap where
    the cut points are sparse, the overlap solved twice, identically) and the last one ends at the last row."""
    steps = _steps(stepping, size, substeps)
    if steps <= PIECE_STEPS or ts.size < 4:
        return None
    state_size = ravel_pytree(system.state_scale())[0].size  # the state's shape: constants, nothing solved
    valid, step = _cut_points(system, signal, ts, t0, stepping, grid_step, size)
    end = ts.size - 1
    cuts = np.flatnonzero(valid[1:-1]) + 1
    spacing = max(int(np.median(np.diff(cuts))), 1) if cuts.size > 1 else 1  # rows between cut points (pwm: 2)
    rows = max(int(end * PIECE_STEPS / steps) // spacing * spacing, spacing, 2)
    if cuts.size == 0 or rows >= end:  # nowhere to cut: solve whole (or refuse)
        _refuse_if_too_big(system, stepping, steps, ts.size, state_size)
        return None
    pieces, first = [], 0
    while first + rows < end:
        last = first + rows
        following = next((j for j in range(last, first, -1) if valid[j]), None)
        if following is None:  # no cut point in this piece: solve whole (or refuse)
            _refuse_if_too_big(system, stepping, steps, ts.size, state_size)
            return None
        pieces.append((first, last, step))
        first = following
    # the last piece: as long as the others where a cut point allows (one program for all), else from `first`
    start = None
    if pieces:
        start = next((j for j in range(min(end - rows, first), pieces[-1][0], -1) if valid[j]), None)
    pieces.append((first if start is None else start, end, step))
    return pieces if len(pieces) > 1 else None


def _cut_points(system, signal, ts, t0, stepping, grid_step, size):
    """(boolean per output row: a piece may end there, the grid_step the pieces are solved with)."""
    if stepping == "grid":
        h = (float(ts[-1]) - t0) / size  # the whole run's uniform step (<= grid_step)
        k = (ts - t0) / h
        valid = np.abs(k - np.round(k)) < _NODE_TOL
        # each piece spans a whole number of these steps: asked for a step a hair above h, its step count rounds
        # to exactly that number (num_grid_steps: ceil(span / step - 1e-9))
        return valid, h * (1.0 + 1e-10)
    frequency = float(system.valve.pwm_frequency)
    k = ts * frequency
    on_start = np.abs(k - np.round(k)) < 1e-9 * np.maximum(1.0, np.abs(k))
    valid = np.zeros(ts.size, dtype=bool)
    rows = np.flatnonzero(on_start & (ts > t0))
    if rows.size:
        first = math.floor(t0 * frequency + 1e-9) / frequency

        @jax.jit
        def closed(starts):  # the valve closed at these period starts of the whole run (its grid's own rule)
            return ~jax.vmap(lambda s: _sync.open_at_start(system.valve, signal, s, first))(starts)

        valid[rows] = np.asarray(closed(jnp.asarray(np.round(k[rows]) / frequency)))
    return valid, grid_step


def _available_memory():
    """Bytes of memory available to this process (Linux: MemAvailable), None where unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _refuse_if_too_big(system, stepping, steps, rows, state_size):
    need = steps * bytes_per_step(system, state_size) + rows * 8 * 4 * (state_size + 8)
    have = _available_memory()
    if have is None or need <= 0.8 * have:
        return
    on = "PWM period starts" if stepping == "pwm" else "multiples of its grid step"
    raise PamjaxInputError(
        f"this fixed-grid run ({steps:,} steps, '{stepping}') needs about {need / 2**30:.1f} GB of memory to solve in "
        f"one piece, more than the {have / 2**30:.1f} GB available, and none of its output times lies where it could "
        f"be cut into pieces (output times at {on}, with the valve closed there for 'pwm'); give output times on its "
        "grid (e.g. ts = t0 + 0.01 * k), or shorten the run")


def join(pieces, ts):
    """One `Trajectory` from the pieces (first row, last row, trajectory); a piece's rows up to its predecessor's
    last are that predecessor's (an overlap solved twice, or the shared cut row), dropped. A failed piece ends the
    run: its result code is the run's, and the rows after it are NaN."""
    from .trajectory import Trajectory

    parts, result, steps, done = [], 0, [0, 0, 0], -1
    for first, last, traj in pieces:
        skip = done + 1 - first
        parts.append(jax.tree_util.tree_map(lambda a: np.asarray(a)[skip:], (traj.state, traj.command,
                                                                             traj.outputs)))
        done = last
        steps = [steps[0] + int(traj.num_steps), steps[1] + int(traj.num_accepted_steps),
                 steps[2] + int(traj.num_rejected_steps)]
        if int(traj.result) != 0:
            result = int(traj.result)
            break
    if done < ts.size - 1:  # after a failure: NaN rows, never plausible numbers
        parts.append(jax.tree_util.tree_map(lambda a: np.full((ts.size - 1 - done,) + np.shape(a)[1:], np.nan),
                                            parts[-1]))
    state, command, outputs = jax.tree_util.tree_map(lambda *a: jnp.asarray(np.concatenate(a)), *parts)
    if result != 0:
        outputs = jax.tree_util.tree_map(lambda a: jnp.full_like(a, jnp.nan), outputs)
    template = pieces[0][2]

    def count(value, like):
        return jnp.asarray(value, dtype=jnp.asarray(like).dtype)

    return Trajectory(t=jnp.asarray(ts, dtype=float), state=state, command=command, outputs=outputs,
                      num_steps=count(steps[0], template.num_steps),
                      num_accepted_steps=count(steps[1], template.num_accepted_steps),
                      num_rejected_steps=count(steps[2], template.num_rejected_steps),
                      result=count(result, template.result))


def solve_pieces(solve_on, system, stepping, host, y0, t0, pieces):
    """A fixed-grid run solved piece by piece (`pamjax._solve.chunks`), each from the state its predecessor reached
    at the piece's first row (the start state given to the first too: one compiled program for every piece)."""
    if y0 is None:
        y0 = _initial_state(system)
    done, previous = [], None
    for first, last, step in pieces:
        if previous is not None:
            y0 = jax.tree_util.tree_map(lambda a: a[first - previous[0]], previous[2].state)
        t_start = t0 if first == 0 else jnp.asarray(float(host[first]))
        size = _size(system, stepping, float(t_start), float(host[last]), step)
        traj = solve_on(jnp.asarray(host[first:last + 1]), y0, t_start, size, step)
        previous = (first, last, traj)
        done.append(previous)
        if int(traj.result) != 0:
            break
    return join(done, host)


@eqx.filter_jit
def _initial_state(system):
    return system.initial_state()


def _size(system, stepping, t0, t1, grid_step):
    """The static size of a piece's grid: PWM periods ("pwm") or uniform steps ("grid")."""
    if stepping == "pwm":
        return _sync.num_periods(system.valve, t0, t1)
    return _sync.num_grid_steps(t0, t1, grid_step)
