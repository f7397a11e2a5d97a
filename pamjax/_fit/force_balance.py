"""Start values of a muscle's force law from its recordings' force balance: no solve, one small least-squares
problem.

A muscle run's recording gives, at every sample, the muscle's pressure p and the payload's position x; smoothed over
two PWM periods (local quadratic fits), also its velocity v and acceleration a. Where the payload slides, eq. 16 with
eq. 8-9 holds sample by sample,

    F_static(x, p) = M (g + a) + F_c sign(v) + C_f v,

linear in the force law's coefficients (eq. 7: a0…a4, k0, k1). Where it holds still, the friction bounds the net
force, |F_static − M g| ≤ F_c; where it rests on a stroke limit, the stop holds only one way, and is asked to hold it
without the friction's help (F_static ≥ M g on the upper stop, F_static ≤ M g on the lower: a start whose force law
sits at the friction's edge there, F_static = M g − F_c, lets the simulated payload slide off the stop on the
smallest error elsewhere, and stage 2 then starts far from the recording: on an unseen rig whose muscle holds the
payload on the upper stop at any pressure once it got there, 8.6e8 against 8.5e5 from the start asked for that
margin; benchmarks/RESULTS.md, identify, rig1102); where a run starts at rest in the model's equilibrium (no start
position given) between the stops, F_static = M g there exactly. An experimenter reads a force map that way before
fitting any dynamics, and so does `force_balance`: the equalities as residuals, the bounds as one-sided residuals
where they are violated (a convex problem in the coefficients), and a weak prior (30 N) towards the start model's
force over the stroke and the recorded pressure range, where the recordings may say nothing; it returns the start
model with its force law moved.

The friction's levels are held at their start values: on triangle runs the payload slides up and down at similar
speeds, so F_c sign v and C_f v are nearly collinear with the force law's own terms, and freed they drift to
whatever the force law leaves (C_f → 0 on rig901 below); the dynamics of stage 2 determine them.

Why: a joint fit's stage 2 (`staged_start`) moves the force law through solves of the whole run, which is slow and
can stop in a local minimum when the start model's payload is nowhere near the recorded one. On an unseen rig whose
muscle holds the payload on the upper stroke limit for most of its triangle runs (benchmarks/RESULTS.md, identify:
rig901), the datasheet force law's payload cannot come within 20 mm of where the runs log it, and stage 2 ended at
7× the noise; from the balance's start it converges at the noise. `staged_start` fits stage 2 from this start where
stage 2's cost is the lower one there (both evaluated, one solve each).

The position and pressure are taken as the sensors read them (their offsets, gain and delay are small beside what
this start needs), and only the free parameters the balance depends on move (the force law's, the payload's mass
where it is free); the others keep their values.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.errors import PamjaxInputError
from .builds import PAYLOAD_SHARE, PayloadFromModel
from .experiment import Experiment
from .parameters import ParameterSpace
from .rig import split

SMOOTHING_S = 0.04  # s: two 50 Hz PWM periods (paper 000's valve), the window of the local quadratic fits of x
MIN_SPEED = 5e-3  # m/s: sliding, beside the 10-30 mm/s of paper 000's triangle runs (a fifth of their slowest)
AT_STOP = 1e-3  # m: within this of a stroke limit, a payload at rest is taken to rest on it
MODEL_ERROR_N = 2.0  # N: the balance's error floor per sample (the smoothing's bias, the sensors' small nuisances)
PRIOR_N = 30.0  # N: how far the force law may move from the start model's where the recordings say nothing
START_WINDOW_S = 0.02  # s: the recording's start, averaged (as pamjax.bench reads a run's start)
START_WEIGHT = 10.0  # the equilibrium start's weight against one sample's: it holds exactly, not within the noise
STRIDE = 5  # every 5th sample (1 kHz → 200 Hz): the balance needs no more, and its program stays small
# A fit's muscle runs whose payload slides in fewer than this fraction of their samples (`weak_motion`). Measured on
# the 36 unseen rigs of benchmarks/unseen_rigs.py, realistic1 and the hybrid bench (benchmarks/RESULTS.md, identify,
# Session 50): the six below it (4.5-10.6 % sliding, the payload on a stroke limit the rest of the time) are the six
# whose force law or friction missed 2 % (2.6-42 %; rig1403's F_c +42 % with a standard error of 4 %); the lowest
# above it (31.6 %, rig1002) was within 0.3 %.
WEAK_MOTION = 0.15
# Advise another payload only where it differs from every run's by more than this factor; closer, the runs already
# carry about that payload, and the advice falls back to the duty range (the weights a rig swaps differ far more).
PAYLOAD_MARGIN = 1.2


def _local_quadratic(y, dt, half):
    """Value, slope and curvature×2 (i.e. y, y', y'') of local quadratic least-squares fits over 2 half + 1
    samples (Savitzky-Golay), at the samples half … n − half − 1."""
    k = np.arange(-half, half + 1) * dt
    weights = np.linalg.pinv(np.vander(k, 3, increasing=True))  # rows: value, slope, half the curvature
    window = np.lib.stride_tricks.sliding_window_view(y, 2 * half + 1)
    return window @ weights[0], window @ weights[1], 2.0 * (window @ weights[2]), weights


def _is_muscle_run(e, system):
    """An `Experiment` recording pressure and position of a system with a muscle lifting a payload against friction."""
    return ({"pressure", "position"} <= set(e.channels)
            and all(hasattr(system, a) for a in ("muscle", "friction", "payload_mass", "gravity", "air")))


def _samples(e, system, model):
    """The balance's samples of one muscle run: (x, p, v, a, kind, sigma_a, start), `_classified`'s with `start` the
    run's equilibrium start (`_equilibrium_start`); None as `_classified`."""
    s = _classified(e, system)
    return None if s is None else s + (_equilibrium_start(e, system, model, np.asarray(e.times, dtype=float)),)


def _classified(e, system):
    """(x, p, v, a, kind, sigma_a) of one muscle run on every STRIDE-th sample where both channels are valid, kind 0
    sliding, 1 at rest between the stops, 2 on the upper stop, 3 on the lower (from the recording alone); None when
    the run is too short or not sampled uniformly."""
    t = np.asarray(e.times, dtype=float)
    if t.size < 50:
        return None
    dt = float(np.median(np.diff(t)))
    if not (dt > 0 and np.allclose(np.diff(t), dt, rtol=1e-3, atol=1e-9)):
        return None
    half = max(int(round(SMOOTHING_S / dt / 2)), 2)
    if t.size < 4 * half + 1:
        return None
    x, v, a, weights = _local_quadratic(np.asarray(e.data["position"], dtype=float), dt, half)
    p = _local_quadratic(np.asarray(e.data["pressure"], dtype=float), dt, half)[0]
    valid = np.ones(t.size, dtype=bool)
    for c in ("pressure", "position"):
        valid &= np.asarray(e.weights[c]) > 0
    valid = np.lib.stride_tricks.sliding_window_view(valid, 2 * half + 1).all(axis=1)
    sigma_x = float(e.scales["position"])
    sigma_v = sigma_x * float(np.linalg.norm(weights[1]))
    sigma_a = sigma_x * 2.0 * float(np.linalg.norm(weights[2]))
    lo, hi = float(system.muscle.min_position), float(system.muscle.max_position)
    moving = np.abs(v) > max(MIN_SPEED, 5.0 * sigma_v)
    still = np.abs(v) < max(0.2 * MIN_SPEED, 2.0 * sigma_v)
    kind = np.full(x.size, -1)
    kind[moving] = 0
    kind[still] = 1
    kind[still & (x > hi - AT_STOP)] = 2
    kind[still & (x < lo + AT_STOP)] = 3
    keep = valid & (kind >= 0)
    keep &= np.arange(x.size) % STRIDE == 0
    if not np.any(keep):
        return None
    return tuple(np.asarray(q)[keep] for q in (x, p, v, a, kind)) + (sigma_a,)


def _equilibrium_start(e, system, model, t):
    """(x0, p0) where the run starts at rest in the model's equilibrium (no start position or velocity given, by the
    experiment or a rig's run) and its recording between the stroke limits: there the force law carries the payload
    exactly, F_static(x0, p0) = M g, x0 the recorded mean position over the first 20 ms and p0 the model's start
    pressure; else None."""
    _, _, run = split(model, e.name, e.sensor_group)
    given = set(e.initial) | (set(run.start.keywords()) if run is not None and run.start is not None else set())
    if "position" in given or "velocity" in given:
        return None
    head = t <= t[0] + START_WINDOW_S
    x0 = float(np.mean(np.asarray(e.data["position"])[head]))
    lo, hi = float(system.muscle.min_position), float(system.muscle.max_position)
    if not lo < x0 < hi:
        return None
    return x0, float(e.start_for(system, model).pressure)


def _residuals(theta, space, exps, samples, sigmas, grid, prior):
    """The balance's residuals at the free parameters' θ (`ParameterSpace`'s: positive ones by their logarithm):
    per run, the equalities of the sliding samples and the signed violations of the bounds (positive: violated);
    then the prior's."""
    model = space.model(theta)
    out = []
    for e, (x, p, v, a, kind, _, start), sigma, (_, (fc, cf)) in zip(exps, samples, sigmas, prior):
        system = e.system_for(model)
        force = system.muscle.static_force(x, p, system.air)
        weight = system.payload_mass * system.gravity
        net = force - weight
        out.append(jnp.select(
            [kind == 0, kind == 1, kind == 2],
            [net - system.payload_mass * a - fc * jnp.sign(v) - cf * v, jnp.abs(net) - fc, -net],
            net) / sigma)
        if start is not None:
            x0, p0 = start
            out.append(jnp.atleast_1d(START_WEIGHT * (system.muscle.static_force(x0, p0, system.air) - weight) / sigma))
    for e, (xg, pg), (f0, _) in zip(exps, grid, prior):
        system = e.system_for(model)
        out.append((system.muscle.static_force(xg, pg, system.air) - f0) / PRIOR_N)
    return jnp.concatenate(out)


def _prior(model, exps, grid):
    """What the balance holds: per run, the start model's force law on its grid (the prior's centre) and its
    friction levels (held: see the module docstring)."""
    prior = []
    for e, (xg, pg) in zip(exps, grid):
        system = e.system_for(model)
        levels = tuple(float(getattr(system.friction, k)) for k in ("coulomb_force", "viscous_coefficient"))
        prior.append((np.asarray(system.muscle.static_force(xg, pg, system.air)), levels))
    return prior


@eqx.filter_jit
def _residuals_and_jacobian(theta, space, exps, samples, sigmas, grid, prior):
    def f(t):
        r = _residuals(t, space, exps, samples, sigmas, grid, prior)
        return r, r

    jac, r = jax.jacfwd(f, has_aux=True)(theta)
    return r, jac


def _grid(system, pressures):
    """Where the prior holds the force law: 9 positions over the stroke × 5 pressures from atmospheric to the
    highest recorded."""
    lo, hi = float(system.muscle.min_position), float(system.muscle.max_position)
    atm = float(system.air.atmospheric_pressure)
    xg, pg = np.meshgrid(np.linspace(lo, hi, 9), np.linspace(atm, max(float(np.max(pressures)), atm + 1e5), 5))
    return xg.ravel(), pg.ravel()


def _solve(r, jac, inequality, moving):
    """The Gauss-Newton step on the `moving` columns, the bounds' rows active only where violated."""
    active = ~inequality | (r > 0)
    jm = jac[np.ix_(active, moving)]
    scale = np.linalg.norm(jm, axis=0)
    scale[scale == 0] = 1.0
    step, *_ = np.linalg.lstsq(jm / scale, -r[active], rcond=1e-12)
    return step / scale


def _cost(r, inequality):
    return 0.5 * float(np.sum(np.where(inequality & (r <= 0), 0.0, r) ** 2))


def _sigma(e, system, samples):
    """The balance's standard error per sample [N]: the acceleration's noise times the mass, the pressure's noise
    times the force law's pressure slope, and the error floor."""
    x, p = samples[0], samples[1]
    i = len(x) // 2
    slope = float(system.muscle.static_force(x[i], p[i] + 1e4, system.air)
                  - system.muscle.static_force(x[i], p[i], system.air)) / 1e4
    mass = float(system.payload_mass)
    return float(np.sqrt(MODEL_ERROR_N**2 + (mass * samples[5]) ** 2 + (float(e.scales["pressure"]) * slope) ** 2))


def _gauss_newton(theta, r, jac, args, inequality, moving, max_iterations):
    """Gauss-Newton on the `moving` entries of θ, each step halved until the cost decreases (the cost is convex in
    the force law's coefficients, but a positive parameter's θ is its logarithm); (θ, residuals, cost) at the end."""
    cost = _cost(r, inequality)
    for _ in range(max_iterations):
        step = _solve(r, jac, inequality, moving)
        trial_cost, shrink = np.inf, 1.0
        while shrink > 1e-3:
            trial = theta.copy()
            trial[moving] += shrink * step
            if np.all(np.isfinite(trial)):
                rt, jt = (np.asarray(q) for q in _residuals_and_jacobian(jnp.asarray(trial), *args))
                trial_cost = _cost(rt, inequality)
                if trial_cost < cost:
                    break
            shrink *= 0.5
        if not trial_cost < cost:
            break
        done = cost - trial_cost <= 1e-10 * cost
        theta, r, jac, cost = trial, rt, jt, trial_cost
        if done:
            break
    return theta, r, cost


def force_balance(model: eqx.Module, experiments, free, max_iterations: int = 30):
    """The free parameters of `model` the muscle runs' force balance depends on (the force law's; the payload's mass
    where free), fitted to that balance (module docstring); the others, the friction's levels among them, keep
    their values.

    **Arguments:** as `pamjax.fit`'s `model`, `experiments`, `free`; `max_iterations`: Gauss-Newton steps at most.

    **Returns:** `(model, info)` with `info` a dict (`samples`: per kind, sliding / at rest / on the upper stop / on
    the lower stop; `rms_N`: the sliding samples' balance error [N] at the end; `cost`: start and end;
    `equilibrium_starts`: the runs whose start holds F_static = M g), or None where no experiment is a muscle run
    with pressure and position recorded and a sliding payload, or no free parameter moves the balance.
    """
    space = ParameterSpace(model, free)
    exps, systems, samples = [], [], []
    for e in experiments:
        system = e.system_for(model) if isinstance(e, Experiment) else None
        s = _samples(e, system, model) if system is not None and _is_muscle_run(e, system) else None
        if s is not None:
            exps.append(e)
            systems.append(system)
            samples.append(s)
    if not exps or not any(np.any(s[4] == 0) for s in samples):
        return None
    sigmas = [_sigma(e, sys, s) for e, sys, s in zip(exps, systems, samples)]
    grid = [_grid(sys, s[1]) for sys, s in zip(systems, samples)]
    args = (space, tuple(exps), [tuple(map(jnp.asarray, s[:5])) + s[5:] for s in samples], sigmas, grid,
            _prior(model, exps, grid))
    # the rows' kinds on the host, in the residuals' order: per run its samples' kinds (0-3) and -1 for its
    # equilibrium start, then the prior's rows (-2)
    rows = np.concatenate([np.concatenate([s[4], [-1] if s[6] is not None else []]) for s in samples])
    theta = np.asarray(space.initial_theta(), dtype=float)
    r, jac = (np.asarray(q) for q in _residuals_and_jacobian(jnp.asarray(theta), *args))
    rows = np.concatenate([rows, np.full(r.size - rows.size, -2)])
    moving = np.linalg.norm(jac[rows > -2], axis=0) > 0
    if not np.any(moving):
        return None
    inequality = rows > 0
    start_cost = _cost(r, inequality)
    theta, r, cost = _gauss_newton(theta, r, jac, args, inequality, moving, max_iterations)
    sigma = np.concatenate([np.full(len(s[4]) + (s[6] is not None), sg) for s, sg in zip(samples, sigmas)])
    forces = (r[: sigma.size] * sigma)[rows[: sigma.size] == 0]
    info = dict(samples=[int(np.count_nonzero(rows == k)) for k in range(4)], cost=(start_cost, cost),
                rms_N=float(np.sqrt(np.mean(forces**2))) if forces.size else float("nan"),
                equilibrium_starts=[e.name for e, s in zip(exps, samples) if s[6] is not None])
    return space.model(theta), info


def motion_census(model: eqx.Module, experiments) -> dict[str, list[int]]:
    """Where the payload of each muscle run is, from its recording alone: run name → the balance's samples (every
    STRIDE-th) sliding, at rest between the stops, on the upper stop, on the lower stop."""
    out = {}
    for e in experiments:
        system = e.system_for(model) if isinstance(e, Experiment) else None
        s = _classified(e, system) if system is not None and _is_muscle_run(e, system) else None
        if s is not None:
            out[e.name] = [int(np.count_nonzero(s[4] == k)) for k in range(4)]
    return out


# how `weak_motion`'s warning begins after the runs' names, as `is_weak_motion` recognises it (and
# benchmarks/identify.py, which reads the warnings of joint.json without importing pamjax)
_NEVER, _ONLY = "the payload never slides in the muscle runs", "the payload slides in only"


def is_weak_motion(warning: str) -> bool:
    """Whether a fit's warning is `weak_motion`'s (a band from that fit carries it: `pamjax.FitUncertainty`)."""
    return f": {_NEVER}" in warning or f": {_ONLY}" in warning


def weak_motion(model: eqx.Module, experiments) -> list[str]:
    """A warning where the muscle runs' payload slides in fewer than WEAK_MOTION of their samples: the force law and
    the friction are then fitted from those few samples, the cost has other minima about as low far away (a stuck
    or stopped payload says only that the net force stays within bounds), and the linearised standard errors can
    understate their uncertainty several-fold. Empty otherwise (or without muscle runs)."""
    census = motion_census(model, experiments)
    counts = np.sum(list(census.values()), axis=0) if census else np.zeros(4, dtype=int)
    total = int(counts.sum())
    if total == 0 or counts[0] >= WEAK_MOTION * total:
        return []
    pct = 100.0 * counts / total
    where = (f"{counts[0]} of {total} samples; on a stroke limit {pct[2] + pct[3]:.0f} %, held by friction "
             f"{pct[1]:.0f} %")
    what = (_NEVER + " ({where}): they bound the net force but fix neither the force law "
            "(a0…a4, k0, k1) nor the friction, whose fitted values come from the start and any other runs"
            if counts[0] == 0 else
            _ONLY + " {pct:.0f} % of the muscle runs' samples ({where}): the force law (a0…a4, k0, k1) and the "
            "friction rest on those few samples, where the cost can have other minima about as low far from this "
            "one, so their standard errors may understate the uncertainty several-fold (a profile, "
            "pamjax.profile_likelihood, can find a lower minimum nearby, but its interval follows one valley of the "
            "cost and need not reach the others)")
    advice = _advice(model, experiments, counts)
    return [f"{', '.join(census)}: " + what.format(where=where, pct=pct[0])
            + f"; to identify them, record muscle runs that keep the payload moving ({advice})"]


def _design_advice(counts):
    """How to choose the heavier run's duty: designed at this fit where the payload slid at all (its force law fixed
    somewhere), else E3's triangle first. Where it never slid, the force law is fixed only where the runs held it (on
    a stop: the payload's weight at every pressure), and a design at it stands on nothing (rig3100 of
    benchmarks/design_rigs.py: eq. 7 −1283 N at the lower stop, the design refused to start;
    benchmarks/RESULTS.md, design, Session 60)."""
    if counts[0] > 0:
        return "pamjax design with payload_kg = \"auto\" designs its duty"
    return ("as a wide duty sweep such as E3's triangle: these runs fix the force law only where they held the "
            "payload, so a design at this fit would stand on nothing; once a fit has seen the payload move, pamjax "
            "design with payload_kg = \"auto\" designs its duty")


def _advice(model, experiments, counts):
    """What run would move the payload: a wider duty sweep where friction holds it, else another payload (one
    PAYLOAD_SHARE of the force the muscle pulls at zero contraction and supply pressure) where the runs' payloads are
    all lighter (on the upper stop) or all heavier (on the lower) than that, else another duty range."""
    if counts[1] > counts[2] + counts[3]:
        return "a wider or faster duty sweep: friction holds it still"
    upper = counts[2] >= counts[3]
    systems = [s for e, s in ((e, e.system_for(model)) for e in experiments if isinstance(e, Experiment))
               if _is_muscle_run(e, s)]
    carried = [float(s.payload_mass) for s in systems]
    system = systems[0]
    try:
        mass = float(PayloadFromModel.advised(system).mass)  # PAYLOAD_SHARE of the pull at 0 and supply pressure
    except PamjaxInputError:  # a valve without a supply pressure of its own, a muscle that pulls nothing there
        mass = float("nan")
    force = mass * float(system.gravity) / PAYLOAD_SHARE
    if upper and mass > PAYLOAD_MARGIN * max(carried) or not upper and 0 < mass < min(carried) / PAYLOAD_MARGIN:
        return (f"off the {'upper' if upper else 'lower'} stop: a run with a {'heavier' if upper else 'lighter'} "
                f"payload, about {mass:.0f} kg instead of {max(carried) if upper else min(carried):g} kg — half the "
                f"{force:.0f} N the muscle pulls at zero contraction and supply pressure, which it lifts at high duty "
                "and lets down at low duty; record it with payload_kg in the run's meta.json entry or [[experiment]] "
                "table (pamjax.PayloadFromModel in Python); " + _design_advice(counts))
    return "off the upper stop: a lower top duty" if upper else "off the lower stop: a higher bottom duty"
