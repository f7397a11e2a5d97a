"""Mistakes in a bench folder (issue 33, battery section 5): `fits/joint.py --data DIR`, `pamjax fit` with a
`[bench]` table and `pamjax.bench.load_bench`, each on a small folder a rig might log (CSV in barg and mm, a meta.json),
damaged one way at a time. Every case ends in one named error (exit status 2, no traceback, no output folder left
behind) or, for the folder itself, a correct result.

Cases in the format of `bad_inputs_cli.CASES`: name → (class, expect, run, name_in_message); `register()` adds them
there (`test_bench_cases.py`; `benchmarks/reliability.py` counts every `*_cases.py` in `workflow_cases`).
"""

import contextlib
import importlib.util
import io
import json
import pathlib

import numpy as np

from .bad_inputs_cli import cli

ROOT = pathlib.Path(__file__).resolve().parents[2]
HEADER = "time [s],duty [-],pressure [barg],position [mm]"


def _joint():
    spec = importlib.util.spec_from_file_location("joint", ROOT / "fits" / "joint.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _folder(d):
    """A small rig folder: a tank charge T1 (duty 0.5) and a triangle run M1 (0.2 s each, 1 kHz), plausible values,
    no simulation (the mistakes are found before any)."""
    folder = pathlib.Path(d) / "rig"
    folder.mkdir()
    t = np.arange(0.0, 0.2005, 1e-3)
    rows = {"T1": np.column_stack([t, np.full(t.size, 0.5), 4.0 * t / 0.2, 0 * t]),
            "M1": np.column_stack([t, 0.05 + 0.9 * t, 2.5 * t, -15.0 + 5 * t])}  # from rest: 0 barg at t = 0
    for name, table in rows.items():
        np.savetxt(folder / f"{name}.csv", table, delimiter=",", header=HEADER, comments="", fmt="%.6f")
    meta = dict(experiments=dict(T1=dict(kind="tank_charge", V_tank=5e-5, u=0.5, p0="p_atm"),
                                 # duty 0.05 → 0.95 in 1 s (0.9 per second, as the rows above)
                                 M1=dict(kind="muscle_triangle", lo=0.05, hi=0.95, f_tri=0.5)),
                noise=dict(p_std_Pa=2000.0, x_std_m=1e-4), fitted_keys=["Cv12", "Fc"])
    (folder / "meta.json").write_text(json.dumps(meta))
    return folder


def _meta(change):
    def edit(folder):
        meta = json.loads((folder / "meta.json").read_text())
        change(meta)
        (folder / "meta.json").write_text(json.dumps(meta))
    return edit


def _csv(name, change):
    def edit(folder):
        path = folder / f"{name}.csv"
        head, *rows = path.read_text().splitlines()
        path.write_text("\n".join(change(head, rows)) + "\n")
    return edit


def joint_run(edit):
    """`fits/joint.py --data <damaged folder> --out <new folder>`: (status, text); a left-behind output folder is
    reported in the text as a failure of the case."""
    def run(d):
        folder = _folder(d)
        edit(folder)
        out = pathlib.Path(d) / "out"
        buf_out, buf_err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(buf_out), contextlib.redirect_stderr(buf_err):
            try:
                _joint().main(["--data", str(folder), "--out", str(out), "--no-cache", "--nuisance"])
                status = 0
            except SystemExit as exc:
                status = exc.code if isinstance(exc.code, int) else 1
            except BaseException as exc:  # noqa: BLE001 - the verdict needs every escape
                return None, f"Traceback: {type(exc).__name__}: {exc}"
        text = buf_out.getvalue() + buf_err.getvalue()
        if out.exists():
            return None, text + "\nTraceback: the output folder was left behind"
        return status, text
    return run


def fit_run(edit):
    """`pamjax fit` with `[bench] dir = <damaged folder>`: (status, text)."""
    def run(d):
        folder = _folder(d)
        edit(folder)
        cfg = pathlib.Path(d) / "bench.toml"
        cfg.write_text('[model]\npreset = "mas10_system"\noptions = { valve = "pwm", friction = "karnopp" }\n'
                       f'[bench]\ndir = "{folder}"\nnuisance = true\n')
        return cli("fit", cfg, "--out", pathlib.Path(d) / "out", "--quiet", "--no-plot")
    return run


def _drop(name):
    return lambda f: (f / f"{name}.csv").unlink()


DAMAGE = {
    "missing recording": (_drop("T1"), "'T1' of meta.json has no recording"),
    "NaN sample": (_csv("T1", lambda h, r: [h, *r[:5], "0.005,0.5,nan,0", *r[6:]]), "NaN/inf at row 5"),
    "unsorted times": (_csv("M1", lambda h, r: [h, r[1], r[0], *r[2:]]), "strictly increasing"),
    "duty in percent in meta.json": (_meta(lambda m: m["experiments"]["T1"].update(u=50)), "u = 50"),
    "meta.json duty contradicts the recording": (_meta(lambda m: m["experiments"]["T1"].update(u=0.75)),
                                                 "but its recording's duty is 0.5"),
    "pressure in bar without abs or gauge": (_csv("T1", lambda h, r: [h.replace("barg", "bar"), *r]),
                                             "ABSOLUTE or GAUGE"),
    "position in m holding millimetres": (_csv("M1", lambda h, r: [h.replace("[mm]", "[m]"), *r]), "mm"),
    "time in ms under [s]": (_csv("M1", lambda h, r: [h, *[",".join([str(float(x.split(",")[0]) * 1e3),
                                                                      *x.split(",")[1:]]) for x in r]]), "ms"),
    "empty folder": (lambda f: [p.unlink() for p in f.iterdir()], "has no meta.json"),
    "meta.json syntax error": (lambda f: (f / "meta.json").write_text('{"experiments": {'), "not valid JSON"),
    "folder of CSV without meta.json": (lambda f: (f / "meta.json").unlink(), "holds 2 recording"),
    "triangle without lo": (_meta(lambda m: m["experiments"]["M1"].pop("lo")), "without ['lo']"),
    "zero noise": (_meta(lambda m: m["noise"].update(p_std_Pa=0)), "p_std_Pa must be"),
}
E = "error"
CASES = {f"bench joint.py {k}": ("bench", E, joint_run(edit), message) for k, (edit, message) in DAMAGE.items()}
_VIA_CONFIG = ("duty in percent in meta.json", "meta.json duty contradicts the recording", "triangle without lo",
               "folder of CSV without meta.json")
CASES.update({f"bench pamjax fit {k}": ("bench", E, fit_run(DAMAGE[k][0]), DAMAGE[k][1]) for k in _VIA_CONFIG})


def register():
    """Add these cases to `bad_inputs_cli.CASES` (idempotent); returns their names."""
    from . import bad_inputs_cli

    bad_inputs_cli.CASES.update(CASES)
    return sorted(CASES)
