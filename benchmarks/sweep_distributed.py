"""Benchmark: a 100,000-point averaged-valve sweep on 1 and 2 processes joined by JAX's multi-process runtime.

The sweep: paper 000's MAS-10 + 9.6 kg with the averaged valve (eq. 13), 100,000 constant duties x 5 s, final
pressure and position per point, `sweep`'s default scheme (RODAS5 under per-lane error control). Configurations,
all in this one run, each in fresh processes started by this script (`--worker` is the per-process part):

- `1x1`: one process, one device: the baseline of the efficiency;
- `1x2` (the peer on one machine): one process with two devices (`sweep` shards over them with `shard_map`, no
  `jax.distributed`): what a single machine does without this issue's work;
- `2x1`: two processes with one device each, joined by `pamjax.runtime.initialize_distributed` on localhost (CPU
  collectives over gloo); each computes its devices' points, results gathered on every process.
- on a GPU machine (`--platform gpu`), one process per GPU (`CUDA_VISIBLE_DEVICES`), 1, 2 and every GPU.

Each process times its sweep after a barrier (`multihost_utils.sync_global_devices`): the first call (compilation
and run) and then `--repeats` calls (median), on process 0 up to the moment it holds the whole gathered result.
Start-up (process start to joined, then the first call) is reported apart. Efficiency = throughput /
(processes x the 1x1 throughput). On a shared machine the wall-clock figure moves with the others' load (two busy
processes get two shares of a contended CPU, one gets one), so the CPU time of every process is summed as well:
`cpu_efficiency` = 1x1's CPU time / the configuration's (1: distributing costs no extra work). The results of
every configuration are compared bitwise with 1x1's.
`--chunk-size` (points per device per call, default 5,000: 20 groups, so 1, 2, 4, 5, 10 or 20 devices get equal
shares) fixes each point's arithmetic, so results are comparable across configurations.

    python benchmarks/sweep_distributed.py                       # 100,000 points, 1x1, 1x2, 2x1 on CPU
    python benchmarks/sweep_distributed.py --platform gpu --gpus 8

Ends with `RESULT points=... processes=... pts_per_s=... efficiency=... bitwise_equal=...` (for the largest
process count).
"""

import argparse
import json
import os
import pathlib
import platform
import socket
import subprocess
import sys
import tempfile
import time

import numpy as np


def worker(args):
    """One process of one configuration: join, sweep, time, write process 0's figures (and its result)."""
    start = float(args.spawned)
    import pamjax

    info = pamjax.runtime.initialize_distributed(timeout=120)  # JAX_* environment set by run_configuration
    import jax

    jax.config.update("jax_enable_x64", True)
    from jax.experimental import multihost_utils

    from pamjax import presets

    joined = time.time() - start
    system = presets.mas10_system(valve="averaged")
    ts = np.linspace(0.0, args.horizon, int(round(args.horizon * 10)) + 1)
    duties = np.linspace(0.0, 1.0, args.points)

    def call():
        if jax.process_count() > 1:
            multihost_utils.sync_global_devices("sweep")  # every process starts together
        t, cpu = time.perf_counter(), time.process_time()
        result = pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": duties}, reduce=pamjax.FinalValue(),
                              channels=("pressure", "position"), chunk_size=args.chunk_size, progress=False)
        return result, time.perf_counter() - t, time.process_time() - cpu

    result, first, _ = call()
    timed = [call()[1:] for _ in range(args.repeats)]
    runs, cpu = [t for t, _ in timed], [c for _, c in timed]
    # CPU time of every process (all its threads), summed: the work a configuration does, whatever the load
    cpu_all = np.asarray(multihost_utils.process_allgather(np.asarray(cpu))).reshape(-1, len(cpu)).sum(axis=0) \
        if jax.process_count() > 1 else np.asarray(cpu)
    if jax.process_index() == 0:
        np.savez(pathlib.Path(args.out) / "result.npz", pressure=result["pressure"], position=result["position"],
                 status=result.status)
        figures = dict(joined_s=joined, first_s=first, runs_s=runs, cpu_s=cpu_all.tolist(),
                       processes=jax.process_count(),
                       devices=jax.device_count(), device=str(jax.devices()[0].device_kind),
                       platform=jax.devices()[0].platform, info=str(info),
                       failed=int(np.sum(result.status != 0)), jax=jax.__version__)
        (pathlib.Path(args.out) / "figures.json").write_text(json.dumps(figures))


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_configuration(args, processes, devices_per_process, out):
    """Start `processes` workers (each `devices_per_process` devices), wait, return process 0's figures."""
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "OMPI_"))}
    env["PYTHONPATH"] = os.pathsep.join([str(pathlib.Path(__file__).resolve().parents[1]), env.get("PYTHONPATH", "")])
    command = [sys.executable, __file__, "--worker", "--out", str(out), "--points", str(args.points),
               "--horizon", str(args.horizon), "--repeats", str(args.repeats), "--spawned", repr(time.time())]
    if args.chunk_size:
        command += ["--chunk-size", str(args.chunk_size)]
    procs = []
    for i in range(processes):
        e = dict(env, JAX_COORDINATOR_ADDRESS=f"127.0.0.1:{port}", JAX_NUM_PROCESSES=str(processes),
                 JAX_PROCESS_ID=str(i))
        if args.platform == "cpu":
            e.update(JAX_PLATFORMS="cpu", JAX_NUM_CPU_DEVICES=str(devices_per_process))
        else:
            e["CUDA_VISIBLE_DEVICES"] = ",".join(str(i * devices_per_process + k) for k in range(devices_per_process))
        procs.append(subprocess.Popen(command, env=e, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                      start_new_session=True))
    try:
        texts = [p.communicate(timeout=args.timeout)[0] for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, 9)  # the worker's own session, started above
                p.wait()
    for p, text in zip(procs, texts):
        if p.returncode != 0:
            raise SystemExit(f"a worker of {processes}x{devices_per_process} failed ({p.returncode}):\n{text}")
    return json.loads((out / "figures.json").read_text())


def machine():
    cpu = "?"
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{platform.node()}: {cpu}, {os.cpu_count()} cores, load average {load:.1f} at start"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--horizon", type=float, default=5.0)
    parser.add_argument("--chunk-size", type=int, default=5000, help="points per device per call (0: sweep's own)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=1, help="launch every configuration this many times, in turn "
                                                               "(on a shared machine the load drifts between them)")
    parser.add_argument("--platform", choices=("cpu", "gpu"), default="cpu")
    parser.add_argument("--gpus", type=int, default=1, help="GPUs on this machine (--platform gpu)")
    parser.add_argument("--timeout", type=float, default=1800, help="seconds per configuration before its "
                                                                     "processes are killed")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    parser.add_argument("--spawned", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.points < 1 or args.repeats < 1 or args.horizon <= 0 or args.chunk_size < 0:
        raise SystemExit("bad arguments: points and repeats must be >= 1, horizon > 0, chunk size >= 0")
    args.chunk_size = args.chunk_size or None
    if args.worker:
        return worker(args)

    print(machine())
    if args.platform == "cpu":
        configurations = [(1, 1), (1, 2), (2, 1)]  # (processes, devices per process)
    else:
        configurations = [(1, 1), (2, 1)] + ([(args.gpus, 1)] if args.gpus > 2 else [])
    rows, reference = {}, None
    with tempfile.TemporaryDirectory() as tmp:
        for turn in range(args.rounds):
            for processes, per in configurations:
                out = pathlib.Path(tmp) / f"{processes}x{per}-{turn}"
                out.mkdir()
                spawned = time.time()
                fig = run_configuration(args, processes, per, out)
                fig["wall_s"] = time.time() - spawned
                result = np.load(out / "result.npz")
                if reference is None:
                    reference = {k: result[k] for k in result.files}
                fig["bitwise_equal"] = all(np.array_equal(result[k], reference[k], equal_nan=True)
                                           for k in reference)
                fig["max_rel_diff"] = max(float(np.nanmax(np.abs(result[k] - reference[k]) / np.maximum(
                    np.abs(reference[k]), 1e-300))) for k in ("pressure", "position"))
                run = float(np.median(fig["runs_s"]))
                print(f"{processes} process(es) x {per} {fig['platform']} device(s) ({fig['device']}): run "
                      f"{run:.3f} s (median of {args.repeats}: {', '.join(f'{t:.3f}' for t in fig['runs_s'])}; "
                      f"CPU {float(np.median(fig['cpu_s'])):.2f} s in all processes), "
                      f"{args.points / run:,.0f} points/s; start-up: joined {fig['joined_s']:.1f} s, first call "
                      f"{fig['first_s']:.1f} s, whole launch {fig['wall_s']:.1f} s; failed {fig['failed']}; "
                      f"bitwise equal to 1x1: {fig['bitwise_equal']} (max rel. diff {fig['max_rel_diff']:.1e})",
                      flush=True)
                if (processes, per) not in rows:
                    rows[(processes, per)] = fig
                else:  # pool the rounds: every timed call, start-up per launch
                    row = rows[(processes, per)]
                    row["runs_s"] = row["runs_s"] + fig["runs_s"]
                    row["cpu_s"] = row["cpu_s"] + fig["cpu_s"]
                    for key in ("joined_s", "first_s", "wall_s"):
                        row.setdefault(key + "_all", [row[key]]).append(fig[key])
                        row[key] = float(np.median(row[key + "_all"]))
                    row["bitwise_equal"] = row["bitwise_equal"] and fig["bitwise_equal"]
    base = args.points / float(np.median(rows[(1, 1)]["runs_s"]))
    base_cpu = float(np.median(rows[(1, 1)]["cpu_s"]))
    print(f"jax {rows[(1, 1)]['jax']}, chunk {args.chunk_size or 'default'} points per device per call; medians "
          f"over {args.rounds} round(s) x {args.repeats} calls")
    for (processes, per), fig in rows.items():
        rate = args.points / float(np.median(fig["runs_s"]))
        units = processes * per
        print(f"  {processes}x{per}: {rate:12,.0f} points/s  speed-up {rate / base:5.2f}  efficiency "
              f"{rate / (units * base):5.2f} (over {units} device(s))  CPU work vs 1x1 "
              f"{float(np.median(fig['cpu_s'])) / base_cpu:5.2f}")
    top = max((k for k in rows if k[1] == 1), key=lambda k: k[0])
    fig = rows[top]
    rate = args.points / float(np.median(fig["runs_s"]))
    # start-up paid by a multi-process launch beyond the single process's (joining, a second compilation in
    # parallel): the sweep must save at least this much to be worth it
    overhead = (fig["joined_s"] + fig["first_s"] - float(np.median(fig["runs_s"]))) - (
        rows[(1, 1)]["joined_s"] + rows[(1, 1)]["first_s"] - float(np.median(rows[(1, 1)]["runs_s"])))
    saved_per_point = 1 / base - 1 / rate
    if saved_per_point > 0:
        print(f"extra start-up of {top[0]} processes: {overhead:.1f} s; amortised beyond "
              f"~{max(overhead, 0) / saved_per_point:,.0f} points")
    work = base_cpu / float(np.median(fig["cpu_s"]))  # 1 = no extra CPU work for distributing
    print(f"RESULT points={args.points} processes={top[0]} pts_per_s={rate:.0f} "
          f"efficiency={rate / (top[0] * base):.2f} "
          f"cpu_efficiency={work:.2f} "
          f"single_pts_per_s={base:.0f} one_process_two_devices_pts_per_s="
          f"{args.points / float(np.median(rows[(1, 2)]['runs_s'])) if (1, 2) in rows else float('nan'):.0f} "
          f"bitwise_equal={int(fig['bitwise_equal'])} platform={fig['platform']}")


if __name__ == "__main__":
    main()
