"""`pamjax reproduce [paper000|paper001] [--quick] [--only NAME ...] [--out DIR] [--overwrite | --merge]`: run the
paper gallery (`pamjax.gallery`) and write its index page.

The gallery ships with the package: one script per figure, table or experiment of paper 000 (PWM on/off valve,
MAS-10) and paper 001 (VPPM regulator, DMSP-40), `pamjax.gallery.scripts` (`--scripts DIR` runs a folder of one's
own instead). They run in one process (compiled functions are shared). Each writes its figures and
`<script>.json` into `DIR/<script>/`; `DIR/run.json` holds every script's numbers and `DIR/index.md` the catalogue of
both papers (`pamjax.gallery.catalogue`): every item with pamjax's number beside the paper's and a status computed
from the numbers.

Earlier results are kept or refused, never silently replaced: into a folder holding an earlier run the command runs
only with `--overwrite` (the earlier run is replaced as a whole: its script folders that this run does not write are
removed) or `--merge` (this run's scripts replace theirs, the others' numbers are kept, and the index lists them
all; both runs must be of the same mode). The scripts write into a staging folder that replaces the earlier results
only when every script has finished: an interrupt (or a failing script) leaves the earlier run as it was, and what
finished in `DIR/interrupted-<time>/`, with an index marked INTERRUPTED (or FAILED).
"""

import json
import os
import pathlib
import platform
import shutil
import sys
import time

from .._core import jsonio
from .._core.errors import PamjaxInputError
from ..gallery import catalogue, report, toolkit
from .out import OutputFolder

STAGING = toolkit.REPRODUCE_STAGING  # a script run on its own refuses a folder with these (`toolkit.run_alone`)
INDEX, RUN = toolkit.INDEX_MD, toolkit.RUN_JSON


def add_arguments(parser):
    parser.add_argument("paper", nargs="?", choices=sorted(toolkit.PAPERS.values()), help="one paper only (default: "
                        "both)")
    parser.add_argument("--quick", action="store_true", help="shorter runs and fewer points (what the tests and "
                        "docs/papers.md run)")
    parser.add_argument("--out", default="results/papers", help="output folder (index.md, run.json, one folder per "
                        "script)")
    parser.add_argument("--only", nargs="+", default=None, help="run only these scripts (names, e.g. "
                        "p000_04_flow_curves)")
    parser.add_argument("--scripts", default=None, help="a folder of gallery scripts of one's own (default: the "
                        "package's, pamjax.gallery.scripts)")
    keep = parser.add_mutually_exclusive_group()
    keep.add_argument("--overwrite", action="store_true", help="replace an earlier run in --out")
    keep.add_argument("--merge", action="store_true", help="add this run's scripts to the earlier run in --out "
                      "(same mode), replacing theirs; the index lists both")


def _selection(args):
    """The scripts to run: (names, loader argument per name)."""
    if args.scripts:
        found = {p.stem: p for p in toolkit.folder_scripts(args.scripts)}
    else:
        found = {n: n for n in toolkit.script_names()}
    paper = {v: k for k, v in toolkit.PAPERS.items()}.get(args.paper)
    chosen = {n: s for n, s in found.items() if paper is None or n.startswith(f"p{paper}_")}
    if args.only:
        only = [n[:-3] if n.endswith(".py") else n for n in args.only]
        elsewhere = [n for n in only if n in found and n not in chosen]
        if elsewhere:
            raise PamjaxInputError(f"--only: {', '.join(elsewhere)} belong(s) to "
                                   f"{toolkit.PAPERS[elsewhere[0][1:4]]}, not {args.paper}")
        unknown = sorted(set(only) - set(found))
        if unknown:
            raise PamjaxInputError(f"--only: unknown script(s) {unknown}; the gallery has {sorted(found)}")
        chosen = {n: chosen[n] for n in sorted(set(only))}
    if not chosen:
        raise PamjaxInputError(f"no gallery script to run (paper {args.paper}, --scripts {args.scripts})")
    return chosen


def _check_dependencies():
    missing = []
    for module in ("matplotlib", "scipy"):
        try:
            __import__(module)
        except ImportError:
            missing.append(module)
    if missing:
        raise PamjaxInputError(f"the paper gallery needs {' and '.join(missing)}: pip install 'pamjax[gallery]'")


def _earlier_run(out):
    """The earlier run in `out`: its run.json (a dict), {} for results without one (an index of an older pamjax,
    or gallery folders), None when there is none."""
    path = out / RUN
    if path.is_file():
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError) as err:
            raise PamjaxInputError(f"{path} cannot be read ({err}); move it away or choose another folder with --out")
    if (out / INDEX).exists() or any((out / n).is_dir() for n in toolkit.script_names()):
        return {}
    return None


def _describe(run):
    if not run:
        return "results of an earlier run"
    n = len(run.get("scripts", {}))
    return (f"an earlier run ({n} script{'s' * (n != 1)}, {'quick' if run.get('quick') else 'full mode'}, "
            f"{run.get('state', '?')}, {run.get('finished') or run.get('started', '?')})")


def _check_keep(out, earlier, args):
    """Refuse to replace an earlier run unless asked (`--overwrite`, `--merge`), before any work."""
    if earlier is None:
        if args.merge:
            raise PamjaxInputError(f"--merge: {out} holds no earlier run to merge into; drop --merge")
        return
    if not (args.overwrite or args.merge):
        raise PamjaxInputError(f"{out} holds {_describe(earlier)}; pass --overwrite to replace it, --merge to add "
                               "this run's scripts to it, or choose another folder with --out")
    if args.merge:
        if not earlier.get("scripts"):
            raise PamjaxInputError(f"--merge: {out} holds {_describe(earlier)} without its numbers (no run.json); "
                                   "pass --overwrite, or choose another folder with --out")
        if bool(earlier.get("quick")) != bool(args.quick):
            mode = "quick" if earlier.get("quick") else "full mode"
            raise PamjaxInputError(f"--merge: the earlier run in {out} is {mode}, this one is "
                                   f"{'quick' if args.quick else 'full mode'}; one index does not mix modes: match "
                                   "the mode, pass --overwrite, or choose another folder with --out")


def _new_run(args, planned):
    from .._core.metadata import version

    return dict(format=report.FORMAT, version=1, state="running", quick=bool(args.quick), planned=list(planned),
                scripts_folder=str(args.scripts) if args.scripts else None,
                started=time.strftime("%Y-%m-%d %H:%M:%S"), finished=None, pamjax_version=version(),
                machine=f"{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}",
                scripts={})


def _json(data):
    """Strict JSON text of a run (`pamjax._core.jsonio`: a non-finite number as "nan", "inf" or "-inf")."""
    return jsonio.dumps(data, indent=1, ensure_ascii=False)


def _write_json(path, data):
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(_json(data))
    os.replace(tmp, path)


def _commit(folder, staging, run, earlier, args):
    """Move the staged script folders into place and write run.json and index.md (the merged run with --merge)."""
    out, written = folder.path, list(run["scripts"])
    if args.merge:
        run = dict(earlier, scripts={**earlier.get("scripts", {}), **run["scripts"]}, state="complete",
                   finished=run["finished"], merged=[*earlier.get("merged", []), run["started"]],
                   scripts_folder=earlier.get("scripts_folder") or run.get("scripts_folder"))
    elif earlier is not None:  # --overwrite: the earlier run goes as a whole
        for name in set(earlier.get("scripts", {})) | set(toolkit.script_names()):
            if name not in run["scripts"] and (out / name).is_dir() and (out / name / f"{name}.json").exists():
                shutil.rmtree(out / name)
    for name in written:
        if (out / name).exists():
            shutil.rmtree(out / name)
        os.replace(staging / name, out / name)
    shutil.rmtree(staging, ignore_errors=True)
    folder.write_text(RUN, _json(run))
    folder.write_text(INDEX, report.index_page(run))
    return run


def _keep_partial(out, staging, run, err):
    """After an interrupt or a failing script: what finished goes to `out/interrupted-<time>/` (or `failed-`), with
    its run.json and an index saying so; the earlier run in `out` is untouched. Returns the message."""
    state = "interrupted" if isinstance(err, KeyboardInterrupt) else "failed"
    done = len(run["scripts"])
    if not done:
        shutil.rmtree(staging, ignore_errors=True)
        return f"{state} before any script finished; {out} is as it was"
    run = dict(run, state=state)
    target = stamp = out / f"{state}-{time.strftime('%Y%m%d-%H%M%S')}"
    for k in range(2, 1000):
        if not target.exists():
            break
        target = stamp.with_name(f"{stamp.name}-{k}")
    for name in list(run["planned"]):
        if name not in run["scripts"]:
            shutil.rmtree(staging / name, ignore_errors=True)  # a script cut short: its folder is incomplete
    os.replace(staging, target)
    _write_json(target / RUN, run)
    (target / INDEX).write_text(report.index_page(run))
    return (f"{state} after {done} of {len(run['planned'])} scripts: the results in {out} are as they were; the "
            f"{done} finished are in {target} (index.md there, marked {state.upper()})")


def _recover_stale(out):
    """A staging folder left by a run that was killed outright (no chance to say so) becomes
    `out/interrupted-<time>/` like any interrupted run's. Called with the folder's lock held: no other run owns it."""
    for stale in sorted(out.glob(f"{STAGING}-*")):
        try:
            run = json.loads((stale / RUN).read_text())
        except (OSError, ValueError):
            run = None
        if not run or not run.get("scripts"):
            shutil.rmtree(stale, ignore_errors=True)
            continue
        message = _keep_partial(out, stale, run, KeyboardInterrupt())
        print(f"pamjax reproduce: found the staging folder of a run that was killed: {message}", file=sys.stderr)


def run(args):
    if str(args.out).strip() == "":  # Path('') is '.': an unset `--out "$DIR"` would write into the current folder
        raise PamjaxInputError("pamjax reproduce: the output folder is empty; name one with --out")
    chosen = _selection(args)
    _check_dependencies()
    modules = {name: toolkit.load(source) for name, source in chosen.items()}
    problems = catalogue.coverage_problems({n: tuple(getattr(m, "COVERS", ())) for n, m in modules.items()})
    out = pathlib.Path(args.out)
    earlier = _earlier_run(out)
    _check_keep(out, earlier, args)
    with OutputFolder(out, "pamjax reproduce", [], overwrite=True) as folder:
        _recover_stale(out)
        staging = out / f"{STAGING}-{os.getpid()}"
        staging.mkdir()
        state = _new_run(args, chosen)
        start = time.perf_counter()
        try:
            for name, module in modules.items():
                print(f"[{time.perf_counter() - start:6.1f} s] {name}: {module.TITLE}", flush=True)
                record = toolkit.run_script(module, staging, args.quick)
                state["scripts"][name] = record
                _write_json(staging / RUN, state)  # what finished so far, should the run stop here
                for v in catalogue.verdicts_of({name: record}, scripts=[name]):
                    print(f"    {v.entry.item}: {v.status} | pamjax {v.pamjax}", flush=True)
        except BaseException as err:
            print(f"pamjax reproduce: {_keep_partial(out, staging, state, err)}", file=sys.stderr, flush=True)
            raise
        state.update(state="complete", finished=time.strftime("%Y-%m-%d %H:%M:%S"))
        merged = _commit(folder, staging, state, earlier, args)
    total = time.perf_counter() - start
    broken = [v for v in report.verdicts(merged) if v.status == catalogue.MISSING_NUMBER]
    print(f"wrote {out / INDEX} ({len(state['scripts'])} scripts, {total:.0f} s)")
    for line in problems + [f"{v.entry.item} ({v.entry.script}): {v.reading}" for v in broken]:
        print(f"pamjax reproduce: catalogue: {line}", file=sys.stderr)
    return 1 if problems or broken else 0
