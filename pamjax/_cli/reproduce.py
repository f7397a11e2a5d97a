"""`pamjax reproduce [paper000|paper001] [--quick]`: run the gallery of paper reproductions and write its index page.

The gallery is `fits/papers/` of a source checkout: one script per figure, table or experiment of paper 000 (PWM on/off
valve, MAS-10) and paper 001 (VPPM regulator, DMSP-40). Each script has

- `PAPER` ("000" or "001"), `TITLE`, `COVERS` (the equations, tables, figures and text results it reproduces, named as
  in `CATALOGUE`), and
- `run(out, quick)`, which writes its figure(s) to the folder `out` and returns a `Result` (rows for the index, the
  numbers, the paper's numbers).

`pamjax reproduce` runs them in one process (compiled functions are shared), writes `<out>/<script>/<script>.json`
beside each figure, and `<out>/index.md`: every row (item, paper, pamjax, reading of the difference, figure) and the
coverage of both papers, where every item of `CATALOGUE` is either reproduced by a script or listed in
`NOT_REPRODUCED` with the reason. Each script also runs alone: `python fits/papers/<script>.py [--quick] [--out DIR]`.
"""

import dataclasses
import importlib.util
import json
import os
import pathlib
import platform
import sys
import time

from .._core.errors import PamjaxInputError

GALLERY = pathlib.Path(__file__).resolve().parents[2] / "fits" / "papers"
PAPERS = {"000": "paper000", "001": "paper001"}


def _items(prefix, numbers):
    return [f"{prefix} {n}" for n in numbers]


# Every equation, table and figure of both papers, and the results their text states without a figure.
CATALOGUE = {
    "000": [
        *_items("eq.", range(1, 22)),
        "Table 1",
        *_items("Fig.", range(1, 17)),
        "text: switching time 2 ms, usable duty 10-90 %",
        "text: pressure ripple ≈ 15 kPa",
        "text: 25 Hz PWM chatters, 100 Hz is coarse",
        "text: derivative term works in simulation, fails with measurement noise",
        "text: exhaust silencer explains Fig. 12's offset",
        "text: largest error on the way down (no transition between loop branches)",
    ],
    "001": [
        *_items("eq.", range(1, 15)),
        "Table 1",
        "Table 2",
        *_items("Fig.", range(1, 15)),
        "text: G_Vref identified with 94.64 % fit (60/40 split, Butterworth 20 Hz)",
        "text: bandwidths 3.12 Hz (P_out/V_ref) and 3.69 Hz (P_out/Q_in)",
        "text: peak valve inflow 2.79 / 4.34 l/min at 3 / 5 V",
        "text: future work, antagonistic pair on an ankle joint",
        "text: VPPM specification (2 % accuracy, 50 mbar hysteresis, fast / universal / precise modes)",
    ],
}

# Items no script can reproduce, with the reason.
NOT_REPRODUCED = {
    "000": {
        "Fig. 1": "hardware only: a photograph/schematic of the bench (regulator, MHE2 valve, muscle, sensors)",
    },
    "001": {
        "Fig. 1": "hardware only: block diagram of the VPPM's internal control loop (no numbers)",
        "Fig. 2": "hardware only: schematic of the test bench",
        "Fig. 3": "no data: the static calibration curve is printed without values; pamjax uses eq. 6's 1.01 bar/V "
                  "(`VoltageCalibration`), which the figure's straight line agrees with",
        "Fig. 4": "no numbers: the superposition block diagram of eq. 5, which `LinearRegulator` implements",
    },
}


@dataclasses.dataclass
class Row:
    """One line of the index: `item` (e.g. "Table 1"), `what`, `paper` (its number as printed), `pamjax` (pamjax's
    number), `reading` (one line on the difference), `figure` (file name in the script's folder, or "")."""

    item: str
    what: str
    paper: str
    pamjax: str
    reading: str
    figure: str = ""


@dataclasses.dataclass
class Result:
    """What a gallery script returns: `rows` for the index, `numbers` (pamjax's, JSON-able), `paper` (the paper's)."""

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


_FITS_MODULES = {}


def fits_module(name):
    """A script of `fits/` (e.g. "static_force"), imported by path once: the gallery reuses their procedures."""
    if name not in _FITS_MODULES:
        path = GALLERY.parent / f"{name}.py"
        spec = importlib.util.spec_from_file_location(f"pamjax_fits_{name}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        _FITS_MODULES[name] = module
    return _FITS_MODULES[name]


def bench_folder(name="hybrid-reference-bench"):
    """The hybrid reference bench recordings (`shared/data/<name>`, not in the repository), or None if absent:
    `$PAMJAX_BENCH_DATA`, else `shared/data` beside the checkout, else /work/shared/data."""
    candidates = [os.environ.get("PAMJAX_BENCH_DATA"), GALLERY.parents[2] / "shared" / "data" / name,
                  GALLERY.parents[3] / "shared" / "data" / name, pathlib.Path("/work/shared/data") / name]
    for c in candidates:
        if c and (pathlib.Path(c) / "meta.json").exists():
            return pathlib.Path(c)
    return None


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if hasattr(obj, "tolist"):
        return obj.tolist()
    return obj


def scripts(paper=None, folder=GALLERY):
    """The gallery scripts (paths), sorted, optionally of one paper ("000" or "001")."""
    folder = pathlib.Path(folder)
    if not folder.is_dir():
        raise PamjaxInputError(
            f"the paper gallery {folder} is not there: `pamjax reproduce` runs the scripts of a source checkout "
            "(fits/papers/); pass --scripts DIR"
        )
    prefix = "p" if paper is None else f"p{paper}_"
    return sorted(p for p in folder.glob("p0*.py") if p.name.startswith(prefix))


def load(path):
    """Import a gallery script from its path."""
    path = pathlib.Path(path)
    spec = importlib.util.spec_from_file_location(f"pamjax_gallery_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for name in ("PAPER", "TITLE", "COVERS", "run"):
        if not hasattr(module, name):
            raise PamjaxInputError(f"gallery script {path} lacks {name}")
    return module


def run_script(module, out, quick):
    """Run one gallery script into `out/<name>/`; returns (result, seconds) and writes `<name>.json` there."""
    name = pathlib.Path(module.__file__).stem
    folder = pathlib.Path(out) / name
    folder.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    result = module.run(folder, quick)
    seconds = time.perf_counter() - start
    record = dict(script=name, paper=module.PAPER, title=module.TITLE, covers=list(module.COVERS), quick=quick,
                  seconds=seconds, rows=[dataclasses.asdict(r) for r in result.rows], numbers=result.numbers,
                  paper_numbers=result.paper)
    (folder / f"{name}.json").write_text(json.dumps(_jsonable(record), indent=1, ensure_ascii=False))
    return result, seconds


def coverage(modules):
    """item → where it is reproduced (script names) or why not, per paper; raises if an item is neither."""
    out = {}
    for paper, items in CATALOGUE.items():
        covered = {}
        for m in modules:
            if m.PAPER == paper:
                for item in m.COVERS:
                    if item not in items:
                        raise PamjaxInputError(f"{m.__name__} covers {item!r}, which is not in CATALOGUE[{paper!r}]")
                    covered.setdefault(item, []).append(pathlib.Path(m.__file__).stem)
        out[paper] = {}
        for item in items:
            if item in covered:
                out[paper][item] = ("reproduced", ", ".join(covered[item]))
            elif item in NOT_REPRODUCED.get(paper, {}):
                out[paper][item] = ("not reproduced", NOT_REPRODUCED[paper][item])
            else:
                out[paper][item] = ("missing", "")
    return out


def _cell(text):
    return str(text).replace("|", "\\|").replace("\n", " ")


def index_page(records, cover, quick, total_seconds):
    """The Markdown index: one table per paper (rows of every script) and the coverage lists."""
    lines = [
        "# pamjax against papers 000 and 001: the gallery",
        "",
        f"Generated by `pamjax reproduce{' --quick' if quick else ''}` on {time.strftime('%Y-%m-%d %H:%M')} "
        f"({platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}): {len(records)} "
        f"scripts in {total_seconds:.0f} s. Each figure and `<script>.json` (pamjax's numbers beside the paper's) is "
        "in the script's folder. Paper 000: Festo MAS-10 + MHE2 PWM valve; paper 001: Festo VPPM regulator + DMSP-40.",
        "",
    ]
    titles = {"000": "Paper 000 (PWM on/off valve, MAS-10-300, 9.6 kg)", "001": "Paper 001 (VPPM regulator, DMSP-40)"}
    for paper in ("000", "001"):
        mine = [r for r in records if r["paper"] == paper]
        if not mine:
            continue
        lines += [f"## {titles[paper]}", "", "| item | what | paper | pamjax | reading | figure |",
                  "|---|---|---|---|---|---|"]
        for rec in mine:
            for row in rec["rows"]:
                fig = f"[{row['figure']}]({rec['script']}/{row['figure']})" if row["figure"] else ""
                lines.append("| " + " | ".join(_cell(row[k]) for k in ("item", "what", "paper", "pamjax", "reading"))
                             + f" | {fig} |")
        lines += ["", f"### Coverage of paper {paper}", "", "| item | status | where / why |", "|---|---|---|"]
        for item, (status, where) in cover[paper].items():
            lines.append(f"| {item} | {status} | {_cell(where)} |")
        lines += ["", "| script | title | seconds |", "|---|---|---|"]
        lines += [f"| `{r['script']}` | {_cell(r['title'])} | {r['seconds']:.1f} |" for r in mine]
        lines.append("")
    return "\n".join(lines)


def add_arguments(parser):
    parser.add_argument("paper", nargs="?", choices=sorted(PAPERS.values()), help="one paper only (default: both)")
    parser.add_argument("--quick", action="store_true", help="shorter runs and fewer points (a few minutes in all)")
    parser.add_argument("--out", default="results/papers", help="output folder (index.md, one folder per script)")
    parser.add_argument("--only", nargs="+", default=None, help="run only these scripts (names without .py)")
    parser.add_argument("--scripts", default=str(GALLERY), help="the gallery folder (default: fits/papers)")


def run(args):
    paper = {v: k for k, v in PAPERS.items()}.get(args.paper)
    paths = scripts(paper, args.scripts)
    if args.only:
        unknown = set(args.only) - {p.stem for p in paths}
        if unknown:
            raise PamjaxInputError(f"--only: unknown script(s) {sorted(unknown)}; the gallery has "
                                   f"{[p.stem for p in paths]}")
        paths = [p for p in paths if p.stem in args.only]
    modules = [load(p) for p in paths]
    cover = coverage([load(p) for p in scripts(None, args.scripts)])  # of the whole gallery, whatever is run
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    records, start = [], time.perf_counter()
    for m in modules:
        name = pathlib.Path(m.__file__).stem
        print(f"[{time.perf_counter() - start:6.1f} s] {name}: {m.TITLE}", flush=True)
        result, seconds = run_script(m, out, args.quick)
        for r in result.rows:
            print(f"    {r.item}: paper {r.paper} | pamjax {r.pamjax}", flush=True)
        records.append(dict(script=name, paper=m.PAPER, title=m.TITLE, seconds=seconds,
                            rows=[dataclasses.asdict(r) for r in result.rows]))
    total = time.perf_counter() - start
    index = out / "index.md"
    index.write_text(index_page(records, cover, args.quick, total))
    missing = [(p, i) for p, items in cover.items() for i, (s, _) in items.items() if s == "missing"]
    print(f"wrote {index} ({len(records)} scripts, {total:.0f} s)")
    if missing:
        print(f"not covered: {missing}", file=sys.stderr)
        return 1
    return 0


def script_main(module_name):
    """`python fits/papers/<script>.py [--quick] [--out DIR]`: run one gallery script on its own."""
    import argparse

    import jax

    jax.config.update("jax_enable_x64", True)
    module = sys.modules[module_name]
    parser = argparse.ArgumentParser(description=f"paper {module.PAPER}: {module.TITLE}")
    parser.add_argument("--quick", action="store_true", help="shorter runs and fewer points")
    parser.add_argument("--out", default="results/papers", help="parent folder; the script writes OUT/<script>/")
    args = parser.parse_args()
    result, seconds = run_script(module, args.out, args.quick)
    for r in result.rows:
        print(f"{r.item}: {r.what}\n    paper {r.paper} | pamjax {r.pamjax}\n    {r.reading}")
    print(f"wrote {pathlib.Path(args.out) / pathlib.Path(module.__file__).stem} ({seconds:.1f} s)")
