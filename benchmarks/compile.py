"""Compilation benchmark: how long each workflow waits for XLA, cold and with the persistent cache.

    python benchmarks/compile.py [--repeats 3] [--before REV] [--quick]

Every figure comes from a fresh Python process (compilation is per process), started the way a user starts it:

- `main_job`: the README's main job, `pamjax fit examples/fit_example.toml`, wall time of the whole command. Cold:
  an empty persistent compilation cache; warm: the second run on the cache the first one filled.
- `bench_fit`: a valve-and-friction fit (C_v, b of both valve paths, F_c, C_f: 6 parameters) of all eight bench
  recordings E1–E4 of `shared/data/hybrid-reference-bench` at their 1 kHz, from the presets, exact stick-slip on the
  PWM grid; the fit's own compilation time (`FitResult.compile_s`) with the cache off.
- `joint_fit`: `fits/joint.py`'s fit (15 parameters, same data), its compilation time, cache off.
- `simulate`: `pamjax.simulate` of paper 000's 25 s triangle run with each valve (smoothed PWM, exact edges,
  averaged, and the PWM grid with stick-slip): first call less the second, in `--repeats` fresh processes; the RESULT
  key is the largest of the valves' medians (until 2026-11-24 evening: the largest of one process's four). Since
  2026-11-24 (evening) the process's one-time set-up before any solve — JAX's backend start-up and the lazy import
  of diffrax — is timed apart and printed, not charged to whichever valve comes first (before, ~0.4–0.8 s of it
  sat in the smoothed-PWM figure).

Each row also reports what was compiled (`pamjax.runtime.CompileStats`: programs traced, lowered and compiled, and
seconds). `--before REV` runs the main job of an earlier commit (its own checkout in a temporary git worktree, same
venv) in the same session for the before/after; the issue's other before figures (bench fit 291 s, joint fit 109 s) were
taken by its author on this machine type. Ends with

    RESULT main_job_cold_s=... main_job_warm_s=... bench_fit_compile_s=... joint_fit_compile_s=...
           simulate_compile_s=...
"""

import argparse
import json
import os
import pathlib
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
BENCH = ROOT / ".." / "shared" / "data" / "hybrid-reference-bench"
PAMJAX = [sys.executable, "-m", "pamjax"]

BENCH_FIT = textwrap.dedent("""
    import json, sys, time
    import jax
    jax.config.update("jax_enable_x64", True)
    import pamjax as pj
    with pj.runtime.CompileStats() as stats:
        model = pj.presets.mas10_system(valve="pwm", friction="karnopp")
        bench = pj.bench.load_bench(sys.argv[1], model, fitted_keys=["Cv12", "b12", "Cv23", "b23", "Fc", "Cf"])
        res = pj.fit(model, bench.experiments, bench.free, progress=False)
    print(json.dumps(dict(compile_s=res.compile_s, fit_s=res.fit_s, status=res.status, iterations=res.iterations,
                          stats=dict(count=stats.count, seconds=stats.seconds))))
""")

SIMULATE = textwrap.dedent("""
    import json, time
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import pamjax as pj
    ts = np.linspace(0.0, 25.0, 2501)
    signal = pj.Triangle(0.05, 0.95, 0.08)
    # What a process pays once before its first solve, whatever the valve, measured apart from the compilations:
    # JAX's backend start-up (the first computation) and the lazy import of diffrax (adaptive solves only).
    t0 = time.perf_counter(); jax.block_until_ready(jax.numpy.zeros(()) + 1.0); t1 = time.perf_counter()
    import diffrax  # noqa: F401
    t2 = time.perf_counter()
    out = {"process set-up": dict(backend_s=t1 - t0, diffrax_import_s=t2 - t1)}
    for name, system in (("pwm (smoothed edges)", pj.presets.mas10_system("pwm")),
                         ("exact edges", pj.presets.mas10_system("exact")),
                         ("averaged", pj.presets.mas10_system("averaged")),
                         ("pwm grid, stick-slip", pj.presets.mas10_system("pwm", friction="karnopp"))):
        with pj.runtime.CompileStats() as stats:
            t0 = time.perf_counter(); jax.block_until_ready(pj.simulate(system, signal, ts).position)
            t1 = time.perf_counter(); jax.block_until_ready(pj.simulate(system, signal, ts).position)
            t2 = time.perf_counter()
        out[name] = dict(compile_s=max((t1 - t0) - (t2 - t1), 0.0), run_s=t2 - t1,
                         stats=dict(count=stats.count, seconds=stats.seconds))
    print(json.dumps(out))
""")


def run(cmd, env=None, cwd=None):
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"failed: {' '.join(map(str, cmd))}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}")
    return wall, proc.stdout


def env_with(**extra):
    env = dict(os.environ)
    env.update({k: str(v) for k, v in extra.items()})
    return env


def user_env(**extra):
    """The environment of a user's shell: Python writes its bytecode (a shell with PYTHONDONTWRITEBYTECODE set, as
    some sandboxes have, byte-compiles pamjax's ~90 modules at every start, ~0.3 s)."""
    env = env_with(**extra)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def main_job(repeats, root=ROOT, pythonpath=None):
    """Cold and warm wall times of `pamjax fit examples/fit_example.toml` (fresh processes), `repeats` each. Cold:
    the compilation cache empty; pamjax's bytecode written once before (as by any first import), never timed."""
    extra = dict(PYTHONPATH=pythonpath) if pythonpath else {}
    run(PAMJAX + ["fit", "--help"], user_env(**extra))
    cold, warm = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            extra = dict(PAMJAX_CACHE_DIR=pathlib.Path(tmp) / "cache")
            if pythonpath:
                extra["PYTHONPATH"] = pythonpath
            env = user_env(**extra)
            cmd = PAMJAX + ["fit", str(root / "examples" / "fit_example.toml"), "--quiet"]
            cold.append(run(cmd + ["--out", str(pathlib.Path(tmp) / "a")], env, cwd=tmp)[0])
            warm.append(run(cmd + ["--out", str(pathlib.Path(tmp) / "b")], env, cwd=tmp)[0])
    return cold, warm


def main_job_before(rev, repeats):
    """The main job of an earlier commit (its own worktree; it had no persistent cache: cold = warm)."""
    tmp = pathlib.Path(tempfile.mkdtemp())
    tree = tmp / "before"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "-q", "--detach", str(tree), rev], check=True)
    try:
        walls = []
        for _ in range(repeats):
            out = tmp / f"out{len(walls)}"
            cmd = PAMJAX + ["fit", str(tree / "examples" / "fit_example.toml"), "--quiet", "--out", str(out)]
            walls.append(run(cmd, env_with(PYTHONPATH=tree, PAMJAX_COMPILATION_CACHE=0), cwd=tmp)[0])
        return walls
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False)
        shutil.rmtree(tmp, ignore_errors=True)


def python_json(script, *args):
    wall, out = run([sys.executable, "-c", script, *map(str, args)], env_with(PAMJAX_COMPILATION_CACHE=0))
    return wall, json.loads(out.strip().splitlines()[-1])


def joint_fit(data):
    with tempfile.TemporaryDirectory() as tmp:
        wall, _ = run([sys.executable, str(ROOT / "fits" / "joint.py"), "--data", str(data), "--out", tmp, "--quiet"],
                      env_with(PAMJAX_COMPILATION_CACHE=0))
        summary = json.loads((pathlib.Path(tmp) / "joint.json").read_text())
    return wall, summary


def median(xs):
    return statistics.median(xs) if xs else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--before", default=None, help="an earlier commit whose main job to time beside")
    ap.add_argument("--data", default=str(BENCH))
    ap.add_argument("--quick", action="store_true", help="one repeat, no bench or joint fit")
    args = ap.parse_args()
    repeats = 1 if args.quick else args.repeats
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start")

    cold, warm = main_job(repeats)
    print(f"main job (pamjax fit examples/fit_example.toml): cold {[round(x, 1) for x in cold]} s, "
          f"warm {[round(x, 1) for x in warm]} s")
    if args.before:
        before = main_job_before(args.before, repeats)
        print(f"main job at {args.before}: {[round(x, 1) for x in before]} s (no persistent cache then)")

    runs = [python_json(SIMULATE)[1] for _ in range(repeats)]  # fresh processes: compilation is per process
    setups = [r.pop("process set-up") for r in runs]
    print(f"simulate's process set-up, once per process before any solve (not compilation, not in the figure): "
          f"JAX backend {[round(s['backend_s'], 2) for s in setups]} s, "
          f"diffrax import {[round(s['diffrax_import_s'], 2) for s in setups]} s")
    medians = {}
    for name in runs[0]:
        compiles = [r[name]["compile_s"] for r in runs]
        medians[name] = median(compiles)
        print(f"simulate 25 s triangle, {name}: compile {[round(c, 2) for c in compiles]} s (median "
              f"{medians[name]:.2f}), run {median([r[name]['run_s'] for r in runs]):.3f} s; "
              f"{runs[0][name]['stats']['count']}")
    simulate_compile = max(medians.values())  # the slowest valve's median over the repeats

    bench_compile = joint_compile = float("nan")
    if not args.quick:
        walls, fits = zip(*[python_json(BENCH_FIT, args.data) for _ in range(repeats)])
        bench_compile = median([f["compile_s"] for f in fits])
        print(f"bench fit (6 parameters, E1-E4 at 1 kHz): compile {[round(f['compile_s'], 1) for f in fits]} s, "
              f"fit {[round(f['fit_s'], 1) for f in fits]} s, status {[f['status'] for f in fits]}; "
              f"programs {fits[0]['stats']['count']}, seconds {fits[0]['stats']['seconds']}")
        joints = [joint_fit(args.data) for _ in range(repeats)]
        joint_compile = median([s["compile_s"] for _, s in joints])
        print(f"joint fit (fits/joint.py, 15 parameters): compile {[round(s['compile_s'], 1) for _, s in joints]} s, "
              f"fit {[round(s['fit_s'], 1) for _, s in joints]} s, process {[round(w, 1) for w, _ in joints]} s")
        stages = [[round(st["compile_s"], 1) for st in s.get("stages", [])] for _, s in joints]
        if any(stages):  # the staged start's own problems (pamjax.staged_start), included in the compile figure
            pre = [s.get("joint_precompile") or {} for _, s in joints]
            print(f"  of which the staged start's stages 1 and 2: {stages} s; the joint problem compiled beside them "
                  f"in {[round(p.get('wall_s', 0.0), 1) for p in pre]} s, waited for after them "
                  f"{[round(p.get('waited_s', 0.0), 1) for p in pre]} s; the joint fit's own the rest")
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    print(f"RESULT main_job_cold_s={median(cold):.1f} main_job_warm_s={median(warm):.1f} "
          f"bench_fit_compile_s={bench_compile:.1f} joint_fit_compile_s={joint_compile:.1f} "
          f"simulate_compile_s={simulate_compile:.2f}")


if __name__ == "__main__":
    main()
