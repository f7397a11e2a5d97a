"""Regression guard: every benchmark in a quick mode, each headline time and ratio against the last recorded figures.

    python benchmarks/check.py                      # run, compare with benchmarks/reference.json; exit 1 if worse
    python benchmarks/check.py --only sweep,simulate
    python benchmarks/check.py --pythonpath /path/to/other/checkout   # the same benchmarks on another commit's code
    python benchmarks/check.py --record --runs 3    # measure 3 times, store medians and noise bands as the reference

Each benchmark runs in a fresh process (`CHECKS` below: the script and its quick arguments) and ends with its
`RESULT` line; the figures named there are compared with `benchmarks/reference.json` for this machine class (CPU
model, core count and JAX platform: figures from another class are not compared). A figure moved by more than its
noise band is printed, as better or worse; any worse one makes the exit status 1. The last line is

    RESULT regressions=N checked=M

Noise bands: `--record --runs N` runs every check N times and stores, per figure, the median and a band of twice
the largest deviation of a run from the median (at least `MIN_BAND`, `CPU_BAND` for CPU times, at most `MAX_BAND`
for times and ratios; an absolute band for counts and percentages), so a band is what identical code moved by on
that machine. RESULTS.md
(`## check`) mirrors the reference with its conditions. The shared development machine is noisy (±40 % between
runs minutes apart under load, several times slower at a load average of 15): the `*_cpu_*` figures (the process's
CPU time of single-threaded runs) are what other work on the machine inflates least, and a load far above the
reference's is said. A flagged figure is a reason to measure A/B, not a verdict.
"""

import argparse
import datetime
import json
import os
import pathlib
import platform
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "benchmarks" / "reference.json"
BENCH = ROOT / ".." / "shared" / "data" / "hybrid-reference-bench"
MIN_BAND, MAX_BAND = 0.25, 0.60  # relative bands of times and ratios (see the docstring)
CPU_BAND = 0.15  # the smallest band of a CPU-time figure, which other work on the machine moves less
LOWER, HIGHER = "lower", "higher"


def _figure(better, kind="relative", floor=None, loaded=None):
    """How a figure is compared: which way is better; its band relative (times, ratios) or absolute (counts,
    percentages); `floor`: the smallest band (default `MIN_BAND` for relative ones); `loaded`: whether it is judged
    on a loaded machine (default: not for wall times and ratios of wall times, which other work inflates unevenly)."""
    return dict(better=better, kind=kind, floor=MIN_BAND if floor is None and kind == "relative" else floor,
                loaded=kind == "absolute" if loaded is None else loaded)


def _cpu(better=LOWER):
    """A CPU-time figure: relative, with the smaller floor `CPU_BAND`, judged whatever the load."""
    return _figure(better, floor=CPU_BAND, loaded=True)


# name -> (script and quick arguments (OUT: a temporary folder), {RESULT key: comparison}, timeout [s])
CHECKS = {
    "simulate": (["benchmarks/simulate.py", "--quick"], {
        "averaged_ms": _figure(LOWER), "pwm_ms": _figure(LOWER), "pwm_sync_ms": _figure(LOWER),
        "averaged_cpu_ms": _cpu(), "pwm_cpu_ms": _cpu(), "pwm_sync_cpu_ms": _cpu(),
        "averaged_simulate_ms": _figure(LOWER), "averaged_simulate_cpu_ms": _cpu(),  # simulate() with its checks
        "speedup_averaged_vs_scipy": _figure(HIGHER), "speedup_pwm_vs_scipy": _figure(HIGHER)}, 300),
    "sweep": (["benchmarks/sweep.py", "--quick"], {
        "sweep_avg_s": _figure(LOWER), "speedup_vs_scipy": _figure(HIGHER), "ratio_vs_numba": _figure(HIGHER),
        "sweep_avg_rk4_s": _figure(LOWER), "sweep_avg_ros2_s": _figure(LOWER), "sweep_pwm_s": _figure(LOWER),
        "sweep_avg_cpu_s": _cpu(), "sweep_pwm_cpu_s": _cpu()}, 400),
    "sweep_2dev": (["benchmarks/sweep.py", "--default-only", "--repeats", "5", "--host-devices", "2"], {
        "sweep_avg_s": _figure(LOWER), "sweep_avg_cpu_s": _cpu()}, 300),
    "sweep_throughput": (["benchmarks/sweep_throughput.py", "--points", "8192", "--methods", "rodas5a,ros2",
                          "--repeats", "2", "--check", "1"], {
        "avg_rodas5a_pts_per_s": _figure(HIGHER), "avg_ros2_pts_per_s": _figure(HIGHER)}, 400),
    "sweep_distributed": (["benchmarks/sweep_distributed.py", "--points", "8192", "--repeats", "2"], {
        "pts_per_s": _figure(HIGHER), "single_pts_per_s": _figure(HIGHER)}, 600),
    "compile": (["benchmarks/compile.py", "--quick"], {
        "main_job_cold_s": _figure(LOWER), "main_job_warm_s": _figure(LOWER), "simulate_compile_s": _figure(LOWER)},
        600),
    "fit": (["benchmarks/fit.py", "--skip-scipy"], {
        "fit_s": _figure(LOWER), "compile_s": _figure(LOWER), "max_rel_error": _figure(LOWER, "absolute", 0.01)},
        600),
    "identify": (["benchmarks/identify.py", "--sets", str(BENCH), "--out", "OUT/identify"], {
        "fit_s": _figure(LOWER), "compile_s": _figure(LOWER), "converged": _figure(HIGHER, "absolute", 0.0),
        "max_param_err_pct": _figure(LOWER, "absolute", 0.5)}, 600),
    "unseen_plants": (["benchmarks/unseen_plants.py", "--plants", "1", "--out", "OUT/unseen"], {
        "converged": _figure(HIGHER, "absolute", 0.0), "max_param_err_pct": _figure(LOWER, "absolute", 1.0),
        "fit_s": _figure(LOWER)}, 900),
    "design": (["benchmarks/design.py", "--seeds", "2", "--steps", "2", "--pilot", "none", "--tanks", "shared", "--out",
                "OUT/design"], {
        "design_s": _figure(LOWER), "se_ratio_geomean": _figure(HIGHER, "absolute", 1.0)}, 900),
    "reliability": (["benchmarks/reliability.py", "--quick"], {
        "grad_pass": _figure(HIGHER, "absolute", 0.0), "nan_count": _figure(LOWER, "absolute", 0.0),
        "silent_wrong": _figure(LOWER, "absolute", 0.0), "recovery_rate": _figure(HIGHER, "absolute", 0.2)}, 900),
}


def machine_class():
    """CPU model, logical cores and JAX's default platform (with the accelerator's kind): figures are compared only
    within one class."""
    model = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    code = ("import jax; d = jax.devices()[0]; "
            "print(d.platform if d.platform == 'cpu' else f'{d.platform} {d.device_kind} x{len(jax.devices())}')")
    accelerator = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip()
    return f"{model}, {os.cpu_count()} cores, {accelerator or '?'}"


def parse_result(text):
    """The figures of the last `RESULT key=value ...` line of `text` (numbers; True/False as 1/0)."""
    lines = [line for line in text.splitlines() if line.startswith("RESULT ")]
    if not lines:
        return None
    figures = {}
    for key, value in re.findall(r"(\w+)=(\S+)", lines[-1]):
        value = {"True": "1", "False": "0"}.get(value, value)
        try:
            figures[key] = float(value)
        except ValueError:
            continue
    return figures


def _children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_check(name, pythonpath, out):
    args, wanted, timeout = CHECKS[name]
    args = [a.replace("OUT", str(out)) for a in args]
    env = dict(os.environ, PYTHONPATH=str(pythonpath))  # caches as each benchmark sets them (compile.py's warm run)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    start, cpu = time.perf_counter(), _children_cpu()
    try:
        proc = subprocess.run([sys.executable, *args], cwd=ROOT, env=env, capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, f"timed out after {timeout} s", (time.perf_counter() - start, _children_cpu() - cpu)
    wall = (time.perf_counter() - start, _children_cpu() - cpu)
    figures = parse_result(proc.stdout)
    if proc.returncode != 0 or figures is None:
        tail = (proc.stdout + proc.stderr).strip().splitlines()[-3:]
        return None, f"failed (exit {proc.returncode}): {' | '.join(tail)}", wall
    return {k: figures[k] for k in wanted if k in figures}, None, wall


def band_of(spec, runs):
    """The noise band of a figure from its repeated runs (see the module docstring)."""
    middle = statistics.median(runs)
    if spec["kind"] == "absolute":
        return max(spec["floor"], 2.0 * max(abs(r - middle) for r in runs))
    spread = max(abs(r / middle - 1.0) for r in runs) if middle else 0.0
    return min(MAX_BAND, max(spec["floor"], 2.0 * spread))


def compare(spec, value, ref):
    """(moved beyond the band, worse, the change in words)."""
    reference, band = ref["value"], ref["band"]
    if spec["kind"] == "absolute":
        change = value - reference
        moved = abs(change) > band
        words = f"{change:+.3g} (band ±{band:.3g})"
    else:
        change = value / reference - 1.0 if reference else 0.0
        moved = abs(change) > band
        words = f"{100 * change:+.0f} % (band ±{100 * band:.0f} %)"
    worse = moved and ((change > 0) == (spec["better"] == LOWER))
    return moved, worse, words


def git_commit(path):
    proc = subprocess.run(["git", "-C", str(path), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", str(path), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return (proc.stdout.strip() or "?") + ("+changes" if dirty else "")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=None, help=f"comma-separated checks (default all: {', '.join(CHECKS)})")
    ap.add_argument("--pythonpath", default=str(ROOT), help="the pamjax checkout whose code the benchmarks run")
    ap.add_argument("--reference", default=str(REFERENCE))
    ap.add_argument("--record", action="store_true", help="store this machine class's figures as the reference")
    ap.add_argument("--runs", type=int, default=1, help="runs of every check (with --record: the noise bands)")
    ap.add_argument("--max-load", type=float, default=1.5 * (os.cpu_count() or 1),
                    help="above this load average (at the start or the end), wall times and their ratios are shown "
                         "but not judged; CPU times, counts and errors are (default 1.5 x cores)")
    args = ap.parse_args()
    names = list(CHECKS) if args.only is None else [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in CHECKS]
    if unknown:
        raise SystemExit(f"unknown checks {unknown}; known: {', '.join(CHECKS)}")
    cls = machine_class()
    reference = json.loads(pathlib.Path(args.reference).read_text()) if pathlib.Path(args.reference).exists() \
        else {"machines": {}}
    mine = reference["machines"].get(cls)
    code = git_commit(args.pythonpath)
    load_start = os.getloadavg()[0]
    print(f"machine class: {cls}; code: {args.pythonpath} at {code}; load average {load_start:.1f}")
    if mine is None and not args.record:
        print(f"no reference figures for this machine class in {args.reference} (classes: "
              f"{', '.join(reference['machines']) or 'none'}): nothing to compare; --record stores some")

    runs = {}  # "check.key" -> [values]
    failures = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.runs):
            for name in names:
                figures, error, wall = run_check(name, args.pythonpath, pathlib.Path(tmp) / f"{name}{r}")
                took = f"{wall[0]:.0f} s, CPU {wall[1]:.0f} s"
                if error:
                    failures.append(name)
                    print(f"{name}: {error} ({took})", flush=True)
                    continue
                print(f"{name} ({took}): " + ", ".join(f"{k}={v:g}" for k, v in figures.items()), flush=True)
                for key, value in figures.items():
                    runs.setdefault(f"{name}.{key}", []).append(value)

    regressions = checked = 0
    load = max(load_start, os.getloadavg()[0])
    loaded = load > args.max_load
    if mine is not None and loaded:
        print(f"note: load average {load:.1f} (> {args.max_load:g}): other work inflates wall times unevenly, so "
              f"wall times and their ratios are shown, not judged; re-run on a quieter machine to judge them")
    if mine is not None:
        for full, values in runs.items():
            name, key = full.split(".", 1)
            ref = mine["figures"].get(full)
            if ref is None:
                continue
            spec = CHECKS[name][1][key]
            value = statistics.median(values)
            moved, worse, words = compare(spec, value, ref)
            judged = spec["loaded"] or not loaded
            checked += judged
            if moved:
                regressions += worse and judged
                verdict = ("WORSE" if worse else "better") if judged else "(not judged, loaded) moved"
                print(f"{verdict}: {full} = {value:g} against {ref['value']:g} ({ref.get('commit', mine['commit'])}, "
                      f"{ref.get('date', mine['date'])}, load {ref.get('load_average', '?')}): {words}")
    regressions += len(failures)  # a benchmark that no longer runs is a regression too
    if args.record:
        if failures:
            raise SystemExit(f"not recorded: {', '.join(failures)} failed")
        figures = {}
        for full, values in runs.items():
            name, key = full.split(".", 1)
            spec = CHECKS[name][1][key]
            band = band_of(spec, values) if len(values) > 1 else spec["floor"]
            figures[full] = dict(value=statistics.median(values), band=band, better=spec["better"],
                                 kind=spec["kind"], runs=values, commit=code, date=datetime.date.today().isoformat(),
                                 load_average=round(max(load_start, os.getloadavg()[0]), 1))
        old = (mine or {}).get("figures", {})
        reference["machines"][cls] = dict(commit=code, date=datetime.date.today().isoformat(), runs=args.runs,
                                          load_average=round(os.getloadavg()[0], 1),
                                          figures={**old, **figures})
        pathlib.Path(args.reference).write_text(json.dumps(reference, indent=1) + "\n")
        print(f"recorded {len(figures)} figures for {cls} in {args.reference}")
    print(f"RESULT regressions={regressions} checked={checked}")
    sys.exit(1 if regressions else 0)


if __name__ == "__main__":
    main()
