"""The paper gallery (`pamjax.gallery`, `pamjax reproduce`): every item of both papers is in the catalogue with a
status computed from the numbers; a status cannot contradict its numbers (the verdict is the numbers' comparison with
the paper's, and the tests below make it fail when it should); the audit's comparisons of a model with itself are
procedure checks, not reproductions; `docs/papers.md` is what its numbers (`docs/papers.json`) give; and a fresh quick
run of each script gives the statuses the page shows (so the page is current with the code). Nothing pins pamjax's own
outputs: a number may move as long as its verdict stays.
"""

import dataclasses
import json
import math
import os
import pathlib
import subprocess
import sys
import sysconfig
import venv
import zipfile

import numpy as np
import pytest

from pamjax._cli.main import main
from pamjax.gallery import catalogue, docs, report, toolkit
from pamjax.gallery.catalogue import (
    COMPARE,
    DIFFERS,
    MISSING_NUMBER,
    NOT_IMPLEMENTED,
    NOT_RUN,
    PROCEDURE,
    PROCEDURE_CHECK,
    REPRODUCED,
    AtLeast,
    AtMost,
    Between,
    Check,
    Entry,
    Near,
)

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SCRIPTS = toolkit.script_names()
FAST = {"p000_01_force_laws", "p000_03_friction", "p000_09_discrete", "p000_10_control"}  # each ~10 s on 2 cores


def _documented():
    return json.loads((DOCS / "papers.json").read_text())


def _key(v):
    """What a verdict says: its status and which of its checks hold."""
    return v.status, tuple(sorted(v.holds.items()))


# --- the catalogue ------------------------------------------------------------------------------------------------

def test_every_item_of_both_papers_has_an_entry_and_every_script_its_entries():
    covers = {name: tuple(getattr(toolkit.load(name), "COVERS", ())) for name in SCRIPTS}
    assert catalogue.coverage_problems(covers) == []
    for e in catalogue.entries():
        assert e.kind in catalogue.KINDS
        if e.kind in (COMPARE, PROCEDURE):
            assert e.script in SCRIPTS, f"{e.item}: no script {e.script}"


def test_the_coverage_check_fails_on_a_missing_item_or_a_script_without_entries(monkeypatch):
    items = {**catalogue.ITEMS, "000": [*catalogue.ITEMS["000"], "text: an item nobody catalogued"]}
    monkeypatch.setattr(catalogue, "ITEMS", items)
    assert any("an item nobody catalogued" in p for p in catalogue.coverage_problems())
    monkeypatch.undo()
    problems = catalogue.coverage_problems({"p000_99_new": ("Fig. 7",)})
    assert problems == ["p000_99_new covers 'Fig. 7' but no catalogue entry is computed by it"]


def _entry(kind, target=None, **kwargs):
    return Entry("000", "Fig. 7", "a number", kind, "p000_04_flow_curves", "0.36",
                 (Check("C_v", "fitted/c", target),) if target is not None else (), **kwargs)


def test_a_status_follows_its_numbers():
    near = Near(0.36, abs=0.01, why="one hundredth")
    inside, outside = {"fitted": {"c": 0.365}}, {"fitted": {"c": 0.40}}
    assert catalogue.verdict(_entry(COMPARE, near), inside).status == REPRODUCED
    v = catalogue.verdict(_entry(COMPARE, near, reason="the valve is another"), outside)
    assert v.status == DIFFERS and "0.4 vs 0.36 ± 0.01" in v.reading and "Why: the valve is another" in v.reading
    assert "+0.04" in v.reading  # the difference, both numbers
    assert catalogue.verdict(_entry(COMPARE, near), outside).reading.endswith("The reason is not known.")
    for numbers in (inside, outside):  # truth in, truth out: never a reproduction, whether or not it came out
        v = catalogue.verdict(_entry(PROCEDURE, near), numbers)
        assert v.status == PROCEDURE_CHECK and "reproduced" not in v.reading
    assert "truth recovered" in catalogue.verdict(_entry(PROCEDURE, near), inside).reading
    assert "truth NOT recovered" in catalogue.verdict(_entry(PROCEDURE, near), outside).reading
    for bad in ({"fitted": {}}, {"fitted": {"c": float("nan")}}, {"fitted": {"c": "0.36"}}, {"fitted": {"c": True}}):
        assert catalogue.verdict(_entry(COMPARE, near), bad).status == MISSING_NUMBER
    assert catalogue.verdict(_entry(COMPARE, near), None).status == NOT_RUN
    v = catalogue.verdict(_entry(NOT_IMPLEMENTED, reason="a creep model"), None)
    assert v.status == NOT_IMPLEMENTED and "a creep model" in v.reading


@pytest.mark.parametrize("target, inside, outside", [
    (Near(10.0, rel=0.2), 11.9, 12.1), (Between(3.0, 5.0), 3.0, 2.99), (AtLeast(2.0), 2.0, 1.99),
    (AtMost(1e-12), 0.0, 2e-12), (Near(-0.922, rel=1e-4), -0.92205, -0.9212),
])
def test_targets_hold_inside_and_fail_outside(target, inside, outside):
    assert target.holds(inside) and not target.holds(outside)
    assert target.describe() and isinstance(target.difference(outside), str) and target.difference(outside)


def test_the_audits_comparisons_of_a_model_with_itself_are_procedure_checks():
    """Paper 001 eq. 3 and eq. 11 are identities of pamjax's chamber; paper 000's Figs. 3, 5, 6, Table 1 and paper
    001's Tables 1-2 put the truth in and get it back; Figs. 11-14's references are the bench (pamjax's own
    equations). Paper 001 Fig. 11 re-fits no gain, and no entry compares eq. 6 with a regulator whose pilot is eq. 6."""
    by_item = {}
    for e in catalogue.entries():
        by_item.setdefault((e.paper, e.item), []).append(e)
    for key in [("001", "eq. 3"), ("001", "eq. 11"), ("000", "Fig. 3"), ("000", "Fig. 5"), ("000", "Fig. 6"),
                ("000", "Table 1"), ("001", "Table 1"), ("001", "Table 2"), ("000", "Fig. 11"), ("000", "Fig. 12")]:
        assert all(e.kind == PROCEDURE for e in by_item[key]), key
    for e in catalogue.entries():
        if e.kind == COMPARE:
            text = " ".join([e.what, e.basis] + [str(c.path) for c in e.checks]).lower()
            assert "fitted_gain" not in text and "square_wave_mse" not in text and "identity" not in text, e.item
    fig11 = by_item[("001", "Fig. 11")][0]
    assert [c.path for c in fig11.checks] == ["fig11/mse_bar2/voltage_only", "fig11/mse_bar2/global_printed_gain"]


def test_truth_in_truth_out_is_a_procedure_check_not_a_reproduction():
    """Paper 000 eq. 4 differentiates pamjax's eq. 3 against pamjax's eq. 5; paper 001's eq. 6 and eq. 7 static gains
    and Fig. 9's final value are LinearRegulator's defaults, the printed gains, given back: none can come out
    'differs' except through a bug, so none counts as reproduced."""
    for paper, item in [("000", "eq. 4"), ("001", "eq. 6"), ("001", "eq. 7"), ("001", "Fig. 9")]:
        kinds = {e.kind for e in catalogue.entries() if (e.paper, e.item) == (paper, item)}
        assert kinds and COMPARE not in kinds, (paper, item, kinds)
    for e in catalogue.entries():
        if e.kind == COMPARE:
            assert "in LinearRegulator" not in e.basis and "against its closed-form" not in e.basis, e.item


def test_not_implemented_items_name_what_is_missing():
    missing = {e.item: e.reason for e in catalogue.entries() if e.kind == NOT_IMPLEMENTED}
    for item, word in [("text: sliding mode control with the SVSF state estimator", "SVSF"),
                       ("text: creep near the maximum displacement", "creep"),
                       ("text: VPPM operating modes fast / universal / precise", "modes"),
                       ("text: future work, C and b against the diaphragm aperture", "aperture"),
                       ("text: future work, activation and contraction dynamics", "activation")]:
        assert word in missing[item], item
    assert "assumption" in missing["text: VPPM operating modes fast / universal / precise"]


def test_calibrations_and_assumptions_are_not_reproductions():
    """Where the paper's number was put in (the regulator's internal volume from Fig. 6's 20 %, the 50 mbar loop, the
    10 % volume share by root finding) or a number is assumed (the VPPM's fast / precise modes), the entry is a
    procedure check or not implemented, never a comparison; the loops and the down-stroke of a synthetic plant with a
    branch transition are procedure checks too."""
    by_item = {}
    for e in catalogue.entries():
        by_item.setdefault((e.paper, e.item), []).append(e)
    for key in [("001", "Fig. 6"), ("001", "text: VPPM pressure hysteresis 50 mbar"),
                ("001", "text: VPPM operating modes fast / universal / precise"),
                ("000", "text: largest errors on the way down (no transition between loop branches)")]:
        assert {e.kind for e in by_item[key]} <= {PROCEDURE, NOT_IMPLEMENTED}, key
    calibrated = [e for e in by_item[("001", "Fig. 5")] if "fig5_volume_law/share/rms" in [c.path for c in e.checks]]
    assert calibrated and all(e.kind == PROCEDURE for e in calibrated)
    modes = [e for e in by_item[("001", "text: VPPM operating modes fast / universal / precise")]
             if e.kind == PROCEDURE]
    assert modes and all("ASSUMPTION" in e.basis for e in modes)


def test_put_in_numbers_of_paper_000_are_procedure_checks_over_both_valve_paths():
    """Paper 000 eq. 10's flow curves are made by eq. 11 (eq. 11 wins by construction, against the noise put in), so
    eq. 10 is a procedure check whose reading covers path 2→3 as well as 1→2; the usable duty 10-90 % is the 2 ms
    delay × 50 Hz put in (1 ms gives 5-95 %), as the 100 Hz usable steps are: neither is a reproduction."""
    eq10 = [e for e in catalogue.entries() if (e.paper, e.item) == ("000", "eq. 10")]
    assert eq10 and all(e.kind == PROCEDURE for e in eq10)
    targeted = {c.path for e in eq10 for c in e.checks if c.target is not None}
    assert {"eq10_over_eq11_rmse/inflate", "eq10_over_eq11_rmse/exhaust"} <= targeted
    v = catalogue.verdict(eq10[0], {"eq10_over_eq11_rmse": {"inflate": 7.5, "exhaust": 0.9}})
    assert "truth NOT recovered" in v.reading and not all(v.holds.values())  # path 2→3 counts
    for item in ("text: switching time 2 ms, usable duty 10-90 %",
                 "text: 100 Hz PWM gives a poor duty resolution at 0.1 ms sampling"):
        kinds = {e.kind for e in catalogue.entries() if (e.paper, e.item) == ("000", item)}
        assert kinds and COMPARE not in kinds, (item, kinds)


def test_pwm_ripple_leaves_out_the_slow_motion():
    """Paper 000's PWM ripple (p000_08) is the chattering within a period, not the motion along the triangle: a
    smooth ramp has none at every frequency (measured as the raw peak-to-peak it grew with the period, and the
    25 / 50 / 100 Hz check held without any chattering), and a lopsided ripple on a ramp is measured whole."""
    from pamjax.gallery.scripts import p000_08_pwm_frequency as pwm

    t = np.arange(0.0, 4.0 + 1e-9, 1.0 / pwm.OUTPUT_RATE)
    ramp = 0.015 * t  # 15 mm/s, no chattering
    for f in pwm.FREQUENCIES:
        phase = (t * f + 1e-9) % 1.0
        chatter = 1e-4 * np.where(phase < 0.9, phase / 0.9, (1 - phase) / 0.1)  # 0.1 mm peak to peak
        assert max(pwm.ripple(t, ramp, f)) < 1e-12, f
        assert np.allclose(pwm.ripple(t, ramp + chatter, f), 1e-4, rtol=1e-3), f


# --- docs/papers.md ------------------------------------------------------------------------------------------------

def test_docs_papers_md_is_generated_from_its_numbers():
    ok, expected = docs.current(DOCS)
    assert ok, "docs/papers.md is not what docs/papers.json gives: python -m pamjax.gallery.docs --run"
    run = _documented()
    assert run["quick"] and set(run["scripts"]) == set(SCRIPTS), "docs/papers.json: a complete quick run"
    for v in report.verdicts(run):  # every status shown is the one its numbers give, and none is broken
        assert v.status in catalogue.STATUSES, (v.entry.item, v.status, v.reading)
        assert f"**{v.status}**" in expected


def test_docs_check_command_fails_on_a_stale_page(tmp_path):
    (tmp_path / "papers.json").write_text((DOCS / "papers.json").read_text())
    (tmp_path / "papers.md").write_text((DOCS / "papers.md").read_text().replace("**differs**", "**reproduced**", 1))
    assert docs.main(["--check", "--docs", str(tmp_path)]) == 1
    (tmp_path / "papers.md").write_text((DOCS / "papers.md").read_text())
    assert docs.main(["--check", "--docs", str(tmp_path)]) == 0


def test_docs_from_refuses_a_partial_run_and_names_what_is_missing(tmp_path, capsys):
    """`--from` a run of one script, of a `--scripts` folder or an unfinished run would rewrite the page with the
    other items "not run": refused, naming what is missing, the docs untouched; the complete run gives the page."""
    target = tmp_path / "docs"
    target.mkdir()
    for name in ("papers.md", "papers.json"):
        (target / name).write_text((DOCS / name).read_text())
    full = dict(_documented(), state="complete")
    folder = tmp_path / "run"
    folder.mkdir()

    def from_run(run):
        (folder / "run.json").write_text(json.dumps(run))
        return docs.main(["--from", str(folder), "--docs", str(target)])

    one = dict(full, scripts={SCRIPTS[0]: full["scripts"][SCRIPTS[0]]})
    assert from_run(one) == 2
    err = capsys.readouterr().err
    assert f"{len(SCRIPTS) - 1} of the gallery's {len(SCRIPTS)} scripts did not run" in err and SCRIPTS[-1] in err
    for bad, says in ((dict(full, scripts_folder="mine"), "--scripts"), (dict(full, state="interrupted"), "state"),
                      (dict(full, quick=False), "--quick")):
        assert from_run(bad) == 2 and says in capsys.readouterr().err
    for name in ("papers.md", "papers.json"):
        assert (target / name).read_text() == (DOCS / name).read_text(), name
    assert docs.main(["--from", str(tmp_path / "nowhere"), "--docs", str(target)]) == 2
    assert "nowhere: no such folder" in capsys.readouterr().err
    assert from_run(full) == 0 and (target / "papers.md").read_text() == (DOCS / "papers.md").read_text()
    (target / "papers.json").write_text(json.dumps(docs.trimmed(one)))  # a gutted page, current with its numbers
    (target / "papers.md").write_text(docs.page(docs.trimmed(one)))
    assert docs.main(["--check", "--docs", str(target)]) == 1
    assert "not a complete --quick run" in capsys.readouterr().out


# --- the scripts ---------------------------------------------------------------------------------------------------
# Every script runs once per session: in the installed wheel's `pamjax reproduce --quick` (the last section), whose
# outputs the per-script tests read; running each script in this process as well cost the module ~45 s of a 2-core
# CI run for the same numbers. The quick scripts (FAST) also run in this process, which checks the record a script
# returns against the JSON file it writes (the wheel's run only leaves the file).


def _check_record(name, record, folder):
    """`record` (a script's `<name>.json`, written into `folder`) computes every catalogue entry of the script, with
    finite values, the statuses and holding checks `docs/papers.md` shows, and the figures its entries name."""
    assert record["script"] == name and record["quick"] is True
    mine = catalogue.verdicts_of({name: record}, scripts=[name])
    documented = catalogue.verdicts_of(_documented()["scripts"], scripts=[name])
    assert mine, f"{name} computes no catalogue entry"
    for v, d in zip(mine, documented):
        assert v.status != MISSING_NUMBER, v.reading
        assert all(math.isfinite(x) for x in v.values.values())
        assert _key(v) == _key(d), (f"{name}, {v.entry.item}: now {v.status} {v.holds}, docs/papers.md says {d.status} "
                                    f"{d.holds}; regenerate it (python -m pamjax.gallery.docs --run) if the change is "
                                    "meant")
        if v.entry.figure:
            assert (folder / v.entry.figure).stat().st_size > 10_000, v.entry.figure


@pytest.mark.parametrize("name", sorted(FAST))
def test_script_runs_in_process_and_writes_the_record_it_returns(name, tmp_path):
    record = toolkit.run_script(toolkit.load(name), tmp_path, quick=True)
    written = json.loads((tmp_path / name / f"{name}.json").read_text())
    assert written == json.loads(json.dumps(record))
    _check_record(name, written, tmp_path / name)


@pytest.mark.slow
@pytest.mark.parametrize("name", SCRIPTS)
def test_script_runs_quick_and_gives_the_statuses_the_docs_show(name, installed_wheel_run):
    folder = installed_wheel_run["papers"] / name
    record = json.loads((folder / f"{name}.json").read_text())
    _check_record(name, record, folder)
    assert installed_wheel_run["run"]["scripts"][name]["numbers"] == record["numbers"]


def test_reproduce_command_writes_the_index_and_run(tmp_path, capsys):
    assert main(["reproduce", "paper000", "--quick", "--only", "p000_01_force_laws", "--out", str(tmp_path)]) == 0
    index = (tmp_path / "index.md").read_text()
    assert "| eq. 4 |" in index and "**reproduced**" in index and "**not run**" in index
    assert "[force_laws.png](p000_01_force_laws/force_laws.png)" in index
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["state"] == "complete" and list(run["scripts"]) == ["p000_01_force_laws"]
    out = capsys.readouterr().out
    assert "eq. 4: procedure check" in out and "eq. 5: reproduced" in out  # eq. 4: pamjax against itself
    assert main(["reproduce", "--only", "p999_nothing", "--out", str(tmp_path / "x")]) == 2  # a user error: one line
    err = capsys.readouterr().err
    assert "unknown script(s) ['p999_nothing']" in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


OWN_SCRIPT = """from pamjax.gallery import Result
PAPER = "000"
TITLE = "numbers that are not finite"
COVERS = ()


def run(out, quick=False):
    (out / "figure.png").write_bytes(b"this run's")
    return Result([], {"x": float("nan"), "y": float("inf"), "quick": quick})
"""


@pytest.fixture
def own_script(tmp_path):
    folder = tmp_path / "scripts"
    folder.mkdir()
    (folder / "p000_93_nan.py").write_text(OWN_SCRIPT)
    return folder / "p000_93_nan.py"


def _strict(path):
    return json.loads(path.read_text(), parse_constant=lambda word: pytest.fail(f"{path}: bare {word}, not JSON"))


def _script_main(module, monkeypatch, *argv):
    monkeypatch.setitem(sys.modules, "gallery_test_script", module)
    monkeypatch.setattr(sys, "argv", [module.__file__, *argv])
    toolkit.script_main("gallery_test_script")


def test_a_reproduce_run_is_strict_json_and_a_script_alone_does_not_write_into_it(own_script, tmp_path, monkeypatch):
    """run.json and <script>.json write a non-finite number as "nan" / "inf" (strict JSON, as pamjax.gallery says);
    a script run on its own refuses a `pamjax reproduce` run's folder, --overwrite or not (its index would describe
    results no longer there), and points to `--merge`."""
    out = tmp_path / "papers"
    assert main(["reproduce", "--quick", "--scripts", str(own_script.parent), "--out", str(out)]) == 0
    record = _strict(out / "p000_93_nan" / "p000_93_nan.json")
    assert record["numbers"] == _strict(out / "run.json")["scripts"]["p000_93_nan"]["numbers"]
    assert record["numbers"] == {"x": "nan", "y": "inf", "quick": True}
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    module = toolkit.load(own_script)
    for flags in (("--quick",), ("--quick", "--overwrite")):
        with pytest.raises(SystemExit, match="pamjax reproduce --quick --only p000_93_nan --merge"):
            _script_main(module, monkeypatch, "--out", str(out), *flags)
    with pytest.raises(SystemExit, match="That run is quick and this one full mode"):  # --merge would refuse that
        _script_main(module, monkeypatch, "--out", str(out), "--overwrite")
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_a_script_alone_replaces_its_earlier_results_only_with_overwrite_and_whole(own_script, tmp_path, monkeypatch):
    module = toolkit.load(own_script)
    out = tmp_path / "alone"
    _script_main(module, monkeypatch, "--quick", "--out", str(out))
    folder = out / "p000_93_nan"
    (folder / "stale.png").write_bytes(b"the earlier run's")
    with pytest.raises(SystemExit, match="--overwrite"):
        _script_main(module, monkeypatch, "--out", str(out))
    assert _strict(folder / "p000_93_nan.json")["quick"] is True and (folder / "stale.png").exists()
    _script_main(module, monkeypatch, "--out", str(out), "--overwrite")
    assert _strict(folder / "p000_93_nan.json")["quick"] is False
    assert sorted(p.name for p in folder.iterdir()) == ["figure.png", "p000_93_nan.json"]  # nothing of the earlier
    assert [p.name for p in out.iterdir()] == ["p000_93_nan"]  # no staging folder left


def test_a_verdict_is_a_dataclass_of_its_entry():
    v = catalogue.verdict(_entry(COMPARE, Near(1.0, abs=0.1)), {"fitted": {"c": 1.0}})
    assert dataclasses.asdict(v)["entry"]["item"] == "Fig. 7" and v.values == {"C_v": 1.0} and v.holds == {"C_v": True}


# --- The installed wheel (issue 31). The repository holds what `pamjax reproduce` needs: the wheel, installed in a
# fresh virtual environment outside the checkout, runs the whole quick gallery from its own files (scripts,
# procedures, bench recordings). The environment reuses this interpreter's installed dependencies (a `.pth` line to
# its site-packages: no download of JAX) and installs the wheel with `--no-deps`; building the wheel fetches
# hatchling (network). What is checked: the wheel's contents (`pyproject.toml`'s build targets) and `pamjax.gallery`
# with `pamjax/data` run from them. Its run is the session's one run of every gallery script: the per-script tests
# above read its outputs (the fixture is built by the first of them, whichever runs first; ~85 s alone on the
# 2-core CPU with an empty cache). The environment has no pip of its own: this interpreter's pip installs into it
# (`pip --python`), which spares `ensurepip` (~3 s). Where the wheel cannot be built (no package index for
# its build backend), the scripts run from the checkout for the per-script tests, and only the wheel's test fails.


def _clean_env(home):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env.update(HOME=str(home), MPLBACKEND="Agg")
    return env


def _quick_run(command, work, env):
    """`command` (a `pamjax reproduce --quick --out papers`) run in `work`: its output folder and run.json."""
    run = subprocess.run(command, capture_output=True, text=True, cwd=work, env=env, timeout=900)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    papers = work / "papers"
    return dict(papers=papers, run=json.loads((papers / "run.json").read_text()))


@pytest.fixture(scope="module")
def installed_wheel_run(tmp_path_factory):
    """Build the wheel, install it in a fresh virtual environment outside the checkout and run `pamjax reproduce
    --quick` there, once per session: {"wheel": its file names, "where": pamjax's and the bench's folders as the
    environment imports them, "papers": the run's output folder, "run": its run.json}. Where the wheel cannot be
    built (building fetches the build backend, hatchling: a machine without the package index), the gallery runs
    from this checkout instead ({"build_error": pip's message}), so that the per-script checks still run; the wheel's
    own test then fails with the build's error."""
    tmp_path = tmp_path_factory.mktemp("wheel")
    work = tmp_path / "work"  # outside the checkout: nothing of it on the path
    work.mkdir()
    env = _clean_env(tmp_path)
    wheels = tmp_path / "wheels"
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(wheels), str(ROOT)],
                           capture_output=True, text=True, timeout=600)
    if build.returncode != 0:
        checkout = dict(env, PYTHONPATH=str(ROOT))
        return dict(build_error=build.stdout + build.stderr,
                    **_quick_run([sys.executable, "-m", "pamjax", "reproduce", "--quick", "--out", "papers"], work,
                                 checkout))
    [wheel] = wheels.glob("pamjax-*.whl")
    names = zipfile.ZipFile(wheel).namelist()

    env_dir = tmp_path / "env"
    venv.EnvBuilder(with_pip=False).create(env_dir)  # installed into by this interpreter's pip (`--python`)
    python = env_dir / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    host = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (pathlib.Path(site) / "_host_packages.pth").write_text("\n".join(sorted(host)) + "\n")
    install = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
                              "--no-index", "--quiet", str(wheel)],
                             capture_output=True, text=True, cwd=work, env=env, timeout=300)
    assert install.returncode == 0, install.stdout + install.stderr
    where = subprocess.run([str(python), "-c", "import pamjax, pamjax.gallery.toolkit as t; "
                            "print(pamjax.__file__); print(t.bench_folder())"],
                           capture_output=True, text=True, cwd=work, env=env, check=True).stdout.split()
    return dict(wheel=names, where=where, env=env_dir,
                **_quick_run([str(env_dir / "bin" / "pamjax"), "reproduce", "--quick", "--out", "papers"], work, env))


@pytest.mark.slow
def test_reproduce_runs_from_an_installed_wheel(installed_wheel_run):
    wheel_run = installed_wheel_run
    assert "build_error" not in wheel_run, f"the wheel could not be built: {wheel_run.get('build_error', '')[-3000:]}"
    for needed in ("pamjax/gallery/scripts/p000_01_force_laws.py", "pamjax/gallery/procedures/regulator.py",
                   "pamjax/data/hybrid-reference-bench/E4.npz", "pamjax/data/hybrid-reference-bench/README.md",
                   "pamjax/data/DMSP-20-300_force_map_long.csv"):
        assert needed in wheel_run["wheel"], needed
    env_dir = str(wheel_run["env"])
    assert all(w.startswith(env_dir) for w in wheel_run["where"]), wheel_run["where"]  # the wheel's, not the checkout's
    papers = wheel_run["papers"]
    index = (papers / "index.md").read_text()
    assert "**number missing**" not in index and "**not run**" not in index
    assert wheel_run["run"]["state"] == "complete" and sorted(wheel_run["run"]["scripts"]) == sorted(SCRIPTS)
    assert len(list(papers.glob("p0*/*.png"))) >= 15
