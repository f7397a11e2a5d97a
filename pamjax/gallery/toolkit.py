"""The gallery's toolkit: what a script returns (`Result`), how it draws (`plt`, `save`), where the hybrid bench's
recordings are (`bench_folder`, `bench_params`), and how scripts are found, loaded and run (`script_names`, `load`,
`run_script`, `run_alone`, `script_main`).

A gallery script is a module of `pamjax.gallery.scripts` named `pNNN_MM_topic` (NNN the paper, MM its order) with
`PAPER` ("000" or "001"), `TITLE`, `COVERS` (the paper items whose catalogue entries it computes numbers for) and
`run(out, quick) -> Result`, which writes its figures into the folder `out` and returns its numbers. What the numbers
mean, beside what the paper says, is the catalogue's business (`pamjax.gallery.catalogue`), not the script's.
"""

import dataclasses
import importlib
import importlib.resources
import importlib.util
import json
import os
import pathlib
import pkgutil
import re
import shutil
import sys
import time

from .._core import jsonio
from .._core.errors import PamjaxInputError

PAPERS = {"000": "paper000", "001": "paper001"}
SCRIPT_NAME = re.compile(r"^p(\d{3})_\d{2}_\w+$")
BENCH_ENV = "PAMJAX_BENCH_DATA"  # another copy of the bench recordings (a folder with meta.json)
REQUIRED = ("PAPER", "TITLE", "run")
# what `pamjax reproduce` writes into its output folder beside the script folders (`pamjax._cli.reproduce`)
RUN_JSON, INDEX_MD, REPRODUCE_STAGING = "run.json", "index.md", ".reproduce-partial"


@dataclasses.dataclass
class Row:
    """A script's own line of numbers, kept in its JSON (`rows`): `item`, `what`, `paper` (as printed), `pamjax`
    (formatted numbers), `figure` (file in the script's folder). `reading` is not shown anywhere: readings are
    written by the catalogue from the numbers (`pamjax.gallery.catalogue`)."""

    item: str
    what: str
    paper: str
    pamjax: str
    reading: str = ""
    figure: str = ""


@dataclasses.dataclass
class Result:
    """What a gallery script returns: `rows` (its own lines, see `Row`), `numbers` (pamjax's, JSON-able; the
    catalogue reads its entries' numbers from here by path), `paper` (the paper's numbers the script used)."""

    rows: list
    numbers: dict
    paper: dict = dataclasses.field(default_factory=dict)


def plt():
    """matplotlib.pyplot with the Agg backend (the gallery writes files only)."""
    try:
        import matplotlib
    except ImportError as err:  # pragma: no cover
        raise ImportError("the paper gallery draws figures: pip install 'pamjax[plot]'") from err
    matplotlib.use("Agg")
    import matplotlib.pyplot as pyplot

    return pyplot


def save(fig, out, name):
    """Write `fig` as `out/name` (PNG, 110 dpi), close it and return `name`."""
    fig.tight_layout()
    fig.savefig(pathlib.Path(out) / name, dpi=110)
    plt().close(fig)
    return name


def bench_folder(name="hybrid-reference-bench"):
    """The hybrid reference bench's recordings: `$PAMJAX_BENCH_DATA` if set (a folder with `meta.json`), else the copy
    shipped in the package (`pamjax/data/hybrid-reference-bench`, README there: what they are, how they were made)."""
    override = os.environ.get(BENCH_ENV)
    if override:
        folder = pathlib.Path(override)
        if not (folder / "meta.json").is_file():
            raise PamjaxInputError(f"${BENCH_ENV} = {override}: no meta.json there (a hybrid bench folder has one)")
        return folder
    return pathlib.Path(str(importlib.resources.files("pamjax") / "data" / name))


def bench_params(folder=None):
    """The bench's true parameters (`meta.json`, `params`)."""
    folder = bench_folder() if folder is None else pathlib.Path(folder)
    return json.loads((folder / "meta.json").read_text())["params"]


def script_names(paper=None):
    """The package's gallery scripts (module names, sorted), optionally of one paper ("000" or "001")."""
    from . import scripts as package

    names = sorted(m.name for m in pkgutil.iter_modules(package.__path__) if SCRIPT_NAME.match(m.name))
    return [n for n in names if paper is None or n.startswith(f"p{paper}_")]


def folder_scripts(folder):
    """The gallery scripts (paths, sorted) of a folder of one's own (`pamjax reproduce --scripts DIR`)."""
    folder = pathlib.Path(folder)
    if not folder.is_dir():
        raise PamjaxInputError(f"--scripts {folder}: not a folder of gallery scripts (pNNN_MM_name.py)")
    return sorted(p for p in folder.glob("p*.py") if SCRIPT_NAME.match(p.stem))


def load(script):
    """A gallery script: a module name of `pamjax.gallery.scripts` or a path to a `.py` file; checked for `PAPER`,
    `TITLE` and `run`."""
    path = pathlib.Path(str(script))
    if path.suffix == ".py":
        spec = importlib.util.spec_from_file_location(f"pamjax_gallery_{path.stem}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    else:
        module = importlib.import_module(f"pamjax.gallery.scripts.{script}")
    missing = [name for name in REQUIRED if not hasattr(module, name)]
    if missing:
        raise PamjaxInputError(f"gallery script {script} lacks {', '.join(missing)}")
    if module.PAPER not in PAPERS:
        raise PamjaxInputError(f"gallery script {script}: PAPER must be one of {sorted(PAPERS)}, got {module.PAPER!r}")
    return module


def name_of(module):
    return pathlib.Path(module.__file__).stem


def run_script(module, out, quick):
    """Run one gallery script into `out/<name>/`; returns its record (a dict: script, paper, title, covers, quick,
    seconds, finished, rows, numbers, paper_numbers) and writes it as `<name>.json` there. The record is strict JSON
    (`pamjax._core.jsonio`: a non-finite number as the text "nan", "inf" or "-inf", which the catalogue reads as a
    missing number), and the one returned is the one written."""
    name = name_of(module)
    folder = pathlib.Path(out) / name
    folder.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    result = module.run(folder, quick)
    seconds = time.perf_counter() - start
    record = jsonio.plain(dict(
        script=name, paper=module.PAPER, title=module.TITLE, covers=list(getattr(module, "COVERS", ())), quick=quick,
        seconds=seconds, finished=time.strftime("%Y-%m-%d %H:%M:%S"),
        rows=[dataclasses.asdict(r) for r in result.rows], numbers=result.numbers, paper_numbers=result.paper))
    (folder / f"{name}.json").write_text(jsonio.dumps(record, indent=1, ensure_ascii=False))
    return record


# fits/ script → the package module that now holds what the gallery used from it (`fits_module`)
_PROCEDURES = {"static_force": "force_map", "derive_presets": "force_map", "averaged_valve": "averaged_valve",
               "control": "bench", "valve_tank": "bench", "linearise": "linearised", "regulator": "regulator",
               "stiffness": "stiffness", "ankle": "ankle"}


def fits_module(name):
    """For scripts written against the earlier toolkit, which imported `fits/<name>.py` by path: the package module of
    `pamjax.gallery.procedures` that now holds what the gallery used from it (`fits_module("control").bench_plant`).
    New scripts import `pamjax.gallery.procedures.<module>` directly."""
    if name not in _PROCEDURES:
        raise PamjaxInputError(f"fits/{name}.py has no procedures in the package (pamjax.gallery.procedures has "
                               f"{sorted(set(_PROCEDURES.values()))}); move what the script needs there")
    return importlib.import_module(f"pamjax.gallery.procedures.{_PROCEDURES[name]}")


def refuse_reproduce_folder(out, name, quick):
    """Stop a script run on its own (`script_main`) before any work where `out` holds a `pamjax reproduce` run (its
    run.json or index.md, or the staging folder of one under way): writing `out/<name>/` there would leave the run's
    index and run.json describing results that are no longer there. `--overwrite` does not lift this: the command
    that replaces one script of such a run and rewrites its index is `pamjax reproduce --only NAME --merge`."""
    found = [p.name for p in (out / RUN_JSON, out / INDEX_MD) if p.exists()] + sorted(
        p.name for p in out.glob(f"{REPRODUCE_STAGING}-*"))
    if not found:
        return
    try:
        earlier = json.loads((out / RUN_JSON).read_text()).get("quick")
    except (OSError, ValueError, AttributeError):
        earlier = None  # no readable run.json: its mode is not known
    mode = "quick" if quick else "full mode"
    if earlier is not None and bool(earlier) != bool(quick):
        how = (f"That run is {'quick' if earlier else 'full mode'} and this one {mode} (one index does not mix "
               "modes): choose another folder with --out")
    else:
        how = (f"Run `pamjax reproduce {'--quick ' if quick else ''}--only {name} --merge --out {out}` to replace "
               "this script's results in that run, or choose another folder with --out")
    raise SystemExit(f"{name}: {out} holds a `pamjax reproduce` run ({', '.join(found)}); a script run on its own "
                     f"would leave its index out of step with {out / name}, --overwrite or not. {how}")


def run_alone(module, out, quick, overwrite):
    """What `script_main` does once its arguments are read: refuse, before any work, a folder holding a `pamjax
    reproduce` run (`refuse_reproduce_folder`) or the script's earlier results unless `overwrite`; run the script into
    a staging folder beside them, and only when it has finished replace the earlier `out/<name>/` as a whole (nothing
    of the earlier run is left beside the new files; an interrupted or failing run leaves it as it was)."""
    name, out = name_of(module), pathlib.Path(out)
    refuse_reproduce_folder(out, name, quick)
    folder = out / name
    earlier = [folder] if (folder.is_dir() and any(folder.iterdir())) or folder.is_file() else []
    refuse_existing(f"python -m pamjax.gallery.scripts.{name}", earlier, overwrite)
    staging = out / f".{name}.partial-{os.getpid()}"
    try:
        staging.mkdir(parents=True)
        record = run_script(module, staging, quick)
        if folder.is_dir():
            shutil.rmtree(folder)
        elif folder.exists():
            folder.unlink()
        os.replace(staging / name, folder)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return record


def script_main(module_name):
    """`python -m pamjax.gallery.scripts.<script> [--quick] [--out DIR] [--overwrite]`: run one gallery script on its
    own (float64 on; the script is imported afresh after that, so that its module-level values are float64 too). Its
    earlier results in DIR/<script>/ are replaced only with --overwrite, and a folder holding a `pamjax reproduce`
    run is refused (`run_alone`)."""
    import argparse

    import jax

    jax.config.update("jax_enable_x64", True)
    module = sys.modules[module_name]
    stem = name_of(module)
    if module_name == "__main__" and stem in script_names():
        module = load(stem)
    parser = argparse.ArgumentParser(description=f"paper {module.PAPER}: {module.TITLE}")
    parser.add_argument("--quick", action="store_true", help="shorter runs and fewer points")
    parser.add_argument("--out", default="results/papers", help="parent folder; the script writes OUT/<script>/")
    parser.add_argument("--overwrite", action="store_true", help="replace this script's earlier results in "
                        "OUT/<script>/ (a folder holding a `pamjax reproduce` run is refused whatever the flag)")
    args = parser.parse_args()
    record = run_alone(module, args.out, args.quick, args.overwrite)
    from .catalogue import verdicts_of

    for v in verdicts_of({record["script"]: record}, scripts=[record["script"]]):
        print(f"{v.entry.item} [{v.status}]: {v.entry.what}\n    paper {v.entry.paper_says} | pamjax {v.pamjax}\n"
              f"    {v.reading}")
    print(f"wrote {pathlib.Path(args.out) / stem} ({record['seconds']:.1f} s)")


def refuse_existing(script, paths, overwrite):
    """Stop `script` (a fits/ script's file name) before any work where one of its results `paths` exists and
    `overwrite` is not set: a --quick or trial run must not replace a full run's results."""
    existing = [str(path) for path in paths if pathlib.Path(path).exists()]
    if existing and not overwrite:
        it, verb = ("it", "exists") if len(existing) == 1 else ("them", "exist")
        raise SystemExit(f"{script}: {', '.join(existing)} {verb}; pass --overwrite to replace {it} (or another --out)")
