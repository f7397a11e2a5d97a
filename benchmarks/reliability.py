"""Reliability figures (issue 7): gradients vs finite differences, NaN-safety, failure handling, bad input,
recovery from random starts, determinism.

    python benchmarks/reliability.py                    # full figures (20 gradient sets, 10,000 NaN inputs, ...)
    python benchmarks/reliability.py --quick            # smoke-size
    python benchmarks/reliability.py --only bad_inputs  # the bad-input catalogues alone (a few minutes)
    python benchmarks/reliability.py --only gradients   # the 20 gradient sets alone (--quick: 2)

Ends with `RESULT grad_pass=... worst_grad_rel=... nan_count=... bad_input_named=... recovery_rate=...
deterministic=... workflow_cases=... silent_wrong=... lost_work=... tracebacks=...` (the last four from the file and
command-line catalogue, `tests/reliability/bad_inputs_cli.py` and every `tests/reliability/*_cases.py`: every case a
correct result or a named error).
"""

import argparse
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import pamjax  # noqa: E402
from pamjax import gradient_check, solve  # noqa: E402
from tests.reliability.bad_inputs import CORE_CASES  # noqa: E402
from tests.reliability.helpers import NUMERICAL_SETTINGS, random_pwm_problem  # noqa: E402
from tests.reliability.nan_safety import trajectory_counts, vector_field_counts  # noqa: E402


def gradients(n_sets, periods, rtol=1e-12):
    """Per seeded parameter set: every physical parameter's reverse-mode gradient against central finite differences
    (`gradient_check`'s ladder of relative steps 1e-2 ... 1e-6; per parameter the most consistent neighbouring pair
    is kept: the loss of an adaptive solve is smooth only down to the solver's noise, ~2e-11 of it here, which
    steps of 1e-5 and 1e-6 alone measured instead of the gradient) and against forward mode.
    Forward and reverse mode must agree within 1e-6 relative to the gradient's largest scaled component (normwise;
    per-parameter differences of negligible components are round-off of a 20,000-step solve). A parameter fails
    when its error exceeds 1e-4; it is counted "inconclusive" instead when the finite differences
    themselves disagree across step sizes by more than both 1e-4 and the error (no reference to judge it by)."""
    ts = jnp.linspace(0.0, periods / 50.0, periods + 1)

    def loss(tree, adjoint):
        s, u = tree
        traj = solve(s, u, ts, None, 0.0, rtol=rtol, atol=rtol, adjoint=adjoint, max_steps=400_000)
        return jnp.mean((traj.position / 1e-2) ** 2) + jnp.mean((traj.pressure / 1e5) ** 2)

    passed, worst, worst_modes, worst_name, inconclusive = 0, 0.0, 0.0, "", []
    for seed in range(n_sets):
        t = time.perf_counter()
        r = gradient_check(loss, random_pwm_problem(seed))
        physical = np.array([not any(k in n for k in NUMERICAL_SETTINGS) for n in r["names"]])
        err, cons, names = r["error_fd"][physical], r["fd_consistency"][physical], r["names"][physical]
        unjudged = (err >= 1e-4) & (cons > 1e-4) & (err <= cons)
        failed = (err >= 1e-4) & ~unjudged
        inconclusive += [f"set {seed}: {n} (error {e:.1e}, FD spread {c:.1e})"
                         for n, e, c in zip(names[unjudged], err[unjudged], cons[unjudged])]
        modes = float(r["error_modes_normwise"])
        ok = not failed.any() and modes < 1e-6
        passed += ok
        judged = np.where(unjudged, 0.0, err)
        if judged.max() > worst:
            worst, worst_name = float(judged.max()), str(names[np.argmax(judged)])
        worst_modes = max(worst_modes, modes)
        print(f"  gradient set {seed:2d}: {physical.sum()} parameters, worst judged FD error {judged.max():.1e} "
              f"({names[np.argmax(judged)]}), {unjudged.sum()} inconclusive, fwd/rev {modes:.1e} normwise "
              f"({r['error_modes'].max():.1e} worst single parameter), "
              f"{'pass' if ok else 'FAIL'} ({time.perf_counter() - t:.0f} s)", flush=True)
    for line in inconclusive:
        print(f"  inconclusive: {line}")
    return passed / n_sets, worst, worst_modes, worst_name


def bad_inputs():
    """Core catalogue (parameters, signals, time grids, initial states) plus the fitting workflow's (recordings,
    configs, experiments, fit specifications); FILE_CASES must raise FileExistsError naming `overwrite`."""
    cases = dict(CORE_CASES)
    file_cases = {}
    try:
        from tests.reliability.bad_inputs_fit import FILE_CASES, FIT_CASES

        cases.update({f"fit: {k}": v for k, v in FIT_CASES.items()})
        file_cases = FILE_CASES
    except ImportError:
        print("  (fitting-workflow bad inputs not available)")
    named = 0
    for case, (make, name) in sorted(cases.items()):
        try:
            make()
        except ValueError as err:
            named += name in str(err)
            if name not in str(err):
                print(f"  bad input rejected but not named ({name!r}): {case}: {err}")
            continue
        print(f"  bad input NOT rejected: {case}")
    for case, make in sorted(file_cases.items()):
        try:
            make()
        except FileExistsError as err:
            named += "overwrite" in str(err)
            continue
        print(f"  existing results file NOT protected: {case}")
    return named, len(cases) + len(file_cases)


def determinism():
    """(1) a vmapped batch (`pamjax.sweep`) against a Python loop over the same points and a repeat, bitwise;
    (2) the same fit twice, bitwise; (3) a fit stopped after 3 iterations, checkpointed and resumed, bitwise where
    the uninterrupted fit ends. Also reports how far an adaptive solve under vmap is from its unbatched run."""
    import tempfile

    from tests.reliability.test_fit_determinism import FREE, _fields, _problem

    system = pamjax.presets.mas10_system("averaged")
    ts = np.linspace(0.0, 1.0, 11)
    duties = np.linspace(0.2, 0.8, 5)
    batch = pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": duties}, progress=False)
    loop_equal = all(
        np.array_equal(batch[c][i], pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": duties[i:i + 1]},
                                                 progress=False)[c][0])
        for i in range(duties.size) for c in batch.channels)
    again = pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": duties}, progress=False)
    repeat_equal = all(np.array_equal(batch[c], again[c]) for c in batch.channels)

    def run(u):
        return solve(system, pamjax.Constant(u), jnp.asarray(ts), None, 0.0).position

    vmapped = np.asarray(jax.jit(jax.vmap(run))(jnp.asarray(duties)))
    single = np.stack([np.asarray(jax.jit(run)(u)) for u in duties])
    adaptive_gap = float(np.max(np.abs(vmapped - single)))

    reference = pamjax.fit(*_problem(), FREE, max_steps=30, progress=False)
    same_fit = _fields(pamjax.fit(*_problem(), FREE, max_steps=30, progress=False)) == _fields(reference)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "state.npz")
        pamjax.fit(*_problem(), FREE, max_steps=3, progress=False, checkpoint=path)
        resumed = pamjax.fit(*_problem(), FREE, max_steps=30, progress=False, resume=path)
    resume_equal = _fields(resumed) == _fields(reference)
    print(f"  sweep batch == loop: {loop_equal}, repeat: {repeat_equal}; same fit twice: {same_fit}; "
          f"resumed fit == uninterrupted: {resume_equal}; adaptive solve vmapped vs unbatched: max |dx| = "
          f"{adaptive_gap:.1e} m (round-off, not bitwise)")
    return bool(loop_equal and repeat_equal and same_fit and resume_equal)


def workflow_catalogue():
    """The file and command-line catalogue (issue 15): configs, CSV, units, paths, concurrency, interrupts, resume
    mismatches, solves, the fitted model carried onward; each case a correct result or a named error."""
    from tests.reliability.bad_inputs_cli import CASES, summary

    register_case_modules(CASES)
    t = time.perf_counter()
    counts = summary(report=lambda line: print(line, flush=True))
    classes = sorted({c for c, *_ in CASES.values()})
    print(f"  {counts['ok']}/{counts['total']} cases a correct result or a named error ({', '.join(classes)}); "
          f"silent wrong {counts['silent_wrong']}, lost work {counts['lost_work']}, tracebacks {counts['traceback']}, "
          f"unnamed {counts['unnamed']} ({time.perf_counter() - t:.0f} s)")
    return counts


def register_case_modules(cases):
    """Add the cases of every `tests/reliability/*_cases.py` (each a `CASES` table in `bad_inputs_cli`'s format, e.g.
    `sweep_cases.py`: stick-slip sweeps and the gradient reference) to the catalogue `cases`."""
    import importlib
    import pathlib

    folder = pathlib.Path(__file__).resolve().parents[1] / "tests" / "reliability"
    for path in sorted(folder.glob("*_cases.py")):
        if not path.name.startswith("test_"):  # test_*_cases.py are the pytest modules that run them
            cases.update(importlib.import_module(f"tests.reliability.{path.stem}").CASES)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--only", choices=["bad_inputs", "gradients"], help="run only this part")
    args = parser.parse_args()
    print(f"pamjax reliability, jax {jax.__version__}, {os.cpu_count()} CPUs")
    if args.only == "bad_inputs":
        named, total = bad_inputs()
        print(f"bad input: {named}/{total} cases raise an error naming the field")
        print("file and command-line workflow (bad_inputs_cli.py):")
        w = workflow_catalogue()
        print(f"RESULT bad_input_named={named} workflow_cases={w['total']} silent_wrong={w['silent_wrong']} "
              f"lost_work={w['lost_work']} tracebacks={w['traceback']}")
        return
    n_sets, periods, n_nan = (2, 20, 500) if args.quick else (20, 20, 2375)
    print("gradients vs central finite differences (smooth PWM muscle system, 20 PWM periods, rtol=atol=1e-12):")
    grad_pass, worst, worst_modes, worst_name = gradients(n_sets, periods)
    print(
        f"  pass fraction {grad_pass:.2f}, worst FD error {worst:.1e} ({worst_name}), worst fwd/rev {worst_modes:.1e}"
    )
    if args.only == "gradients":
        print(f"RESULT grad_pass={grad_pass:.3f} worst_grad_rel={worst:.2e} worst_fwd_rev={worst_modes:.2e}")
        return
    t = time.perf_counter()
    vf = vector_field_counts(n_nan, seed=123)
    tr = trajectory_counts(max(16, 10_000 - vf["inputs"]) if not args.quick else 16, seed=7)
    nan_count = vf["nonfinite"] + tr["nonfinite"]
    print(
        f"NaN search: {vf['inputs'] + tr['inputs']} inputs ({vf['inputs']} vector field + Jacobian, {tr['inputs']} "
        f"trajectory + loss + gradient), {nan_count} non-finite values ({time.perf_counter() - t:.0f} s)"
    )
    named, total = bad_inputs()
    print(f"bad input: {named}/{total} cases raise an error naming the field")
    print("file and command-line workflow (bad_inputs_cli.py):")
    w = workflow_catalogue()
    deterministic = determinism()
    print(f"determinism (bitwise): {deterministic}")
    recovery_rate = float("nan")
    try:
        from benchmarks.reliability_recovery import recovery  # provided with the fitting workflow

        recovery_rate = recovery(quick=args.quick)
    except ImportError:
        print("recovery: not measured (no fitting workflow available)")
    print(
        f"RESULT grad_pass={grad_pass:.3f} worst_grad_rel={worst:.2e} nan_count={nan_count} "
        f"bad_input_named={named} recovery_rate={recovery_rate:.3f} deterministic={deterministic} "
        f"workflow_cases={w['total']} silent_wrong={w['silent_wrong']} lost_work={w['lost_work']} "
        f"tracebacks={w['traceback']}"
    )


if __name__ == "__main__":
    main()
