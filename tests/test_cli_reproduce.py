"""`pamjax reproduce` (`pamjax._cli.reproduce`) keeps or refuses, never silently replaces (issue 33): into a folder
holding an earlier run it runs only with `--overwrite` (the earlier run replaced as a whole) or `--merge` (this run's
scripts replace theirs, the others stay in the index); an interrupted or failing run leaves the earlier run as it was
and puts what finished in a folder of its own whose index says so; a run killed outright is found and labelled the same
way by the next.

The runs use small gallery scripts of their own (`--scripts DIR`, no JAX), so they take a second each."""

import json
import os
import pathlib
import textwrap

import pytest

from pamjax._cli.main import main

SCRIPT = '''
import os
import pathlib

from pamjax.gallery import Result, Row

PAPER = "{paper}"
TITLE = "fake script {name}"
COVERS = ()


def run(out, quick=False):
    if os.environ.get("FAKE_STOP") == "{name}":
        raise KeyboardInterrupt()
    if os.environ.get("FAKE_FAIL") == "{name}":
        raise RuntimeError("broken script")
    (pathlib.Path(out) / "figure.png").write_text("{name} " + os.environ.get("FAKE_TAG", ""))
    return Result([Row("eq. 1", "x", "1", "1")], dict(value=1.0, tag=os.environ.get("FAKE_TAG", "")))
'''
NAMES = ("p000_01_first", "p000_02_second", "p001_01_third")


@pytest.fixture
def gallery(tmp_path):
    folder = tmp_path / "gallery"
    folder.mkdir()
    for name in NAMES:
        (folder / f"{name}.py").write_text(textwrap.dedent(SCRIPT.format(name=name, paper=name[1:4])))
    return folder


def _run(gallery, out, *extra, tag="", stop=None, fail=None, monkeypatch=None):
    monkeypatch.setenv("FAKE_TAG", tag)
    for var, value in (("FAKE_STOP", stop), ("FAKE_FAIL", fail)):
        if value:
            monkeypatch.setenv(var, value)
        else:
            monkeypatch.delenv(var, raising=False)
    return main(["reproduce", "--scripts", str(gallery), "--out", str(out), *extra])


def _tags(out):
    return {n: json.loads((out / n / f"{n}.json").read_text())["numbers"]["tag"] for n in NAMES
            if (out / n).is_dir()}


def test_a_second_run_is_refused_without_overwrite_or_merge(gallery, tmp_path, monkeypatch, capsys):
    out = tmp_path / "papers"
    assert _run(gallery, out, tag="first", monkeypatch=monkeypatch) == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert _run(gallery, out, "--only", "p000_02_second", tag="second", monkeypatch=monkeypatch) == 2
    err = capsys.readouterr().err
    assert "holds an earlier run (3 scripts" in err and "--overwrite" in err and "--merge" in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before  # nothing touched
    assert _run(gallery, out, "paper001", tag="second", monkeypatch=monkeypatch) == 2


def test_merge_keeps_the_other_scripts_rows(gallery, tmp_path, monkeypatch):
    out = tmp_path / "papers"
    assert _run(gallery, out, "--only", "p000_01_first", "p001_01_third", tag="first", monkeypatch=monkeypatch) == 0
    assert _run(gallery, out, "--only", "p000_02_second", "p001_01_third", "--merge", tag="second",
                monkeypatch=monkeypatch) == 0
    run = json.loads((out / "run.json").read_text())
    assert set(run["scripts"]) == set(NAMES) and run["state"] == "complete"
    assert {n: r["numbers"]["tag"] for n, r in run["scripts"].items()} == {
        "p000_01_first": "first", "p000_02_second": "second", "p001_01_third": "second"}
    assert _tags(out) == {"p000_01_first": "first", "p000_02_second": "second", "p001_01_third": "second"}
    index = (out / "index.md").read_text()
    assert all(f"`{n}`" in index for n in NAMES)  # every script of both runs is listed


def test_merge_refuses_another_mode_and_an_empty_folder(gallery, tmp_path, monkeypatch, capsys):
    out = tmp_path / "papers"
    assert _run(gallery, out, "--merge", monkeypatch=monkeypatch) == 2
    assert "holds no earlier run" in capsys.readouterr().err and not out.exists()
    assert _run(gallery, out, monkeypatch=monkeypatch) == 0
    assert _run(gallery, out, "--merge", "--quick", monkeypatch=monkeypatch) == 2
    assert "one index does not mix modes" in capsys.readouterr().err


def test_overwrite_replaces_the_earlier_run_as_a_whole(gallery, tmp_path, monkeypatch):
    out = tmp_path / "papers"
    (out / "notes").mkdir(parents=True)
    (out / "notes" / "mine.txt").write_text("a user's file")
    assert _run(gallery, out, tag="first", monkeypatch=monkeypatch) == 0
    assert _run(gallery, out, "--only", "p000_02_second", "--overwrite", tag="second", monkeypatch=monkeypatch) == 0
    assert _tags(out) == {"p000_02_second": "second"}  # no folder of the earlier run is left to mix with this one
    assert list(json.loads((out / "run.json").read_text())["scripts"]) == ["p000_02_second"]
    assert (out / "notes" / "mine.txt").read_text() == "a user's file"


@pytest.mark.parametrize("how", ["interrupt", "failure"])
def test_an_interrupted_or_failing_run_leaves_the_earlier_run_and_says_where_the_rest_is(gallery, tmp_path,
                                                                                         monkeypatch, capsys, how):
    out = tmp_path / "papers"
    assert _run(gallery, out, tag="first", monkeypatch=monkeypatch) == 0
    index, run = (out / "index.md").read_text(), (out / "run.json").read_text()
    stop = dict(stop="p001_01_third") if how == "interrupt" else dict(fail="p001_01_third")
    status = _run(gallery, out, "--overwrite", tag="second", monkeypatch=monkeypatch, **stop)
    assert status == (130 if how == "interrupt" else 1)
    err = capsys.readouterr().err
    state = "interrupted" if how == "interrupt" else "failed"
    assert f"{state} after 2 of 3 scripts" in err and "are as they were" in err
    assert (out / "index.md").read_text() == index and (out / "run.json").read_text() == run
    assert _tags(out) == dict.fromkeys(NAMES, "first")  # the earlier run, whole
    [partial] = out.glob(f"{state}-*")
    assert str(partial) in err
    assert _tags(partial) == {"p000_01_first": "second", "p000_02_second": "second"}
    assert f"**{state.upper()}**: 2 of the run's 3 scripts finished" in (partial / "index.md").read_text()
    assert json.loads((partial / "run.json").read_text())["state"] == state
    assert not list(out.glob(".reproduce-partial-*"))


def test_a_killed_runs_staging_folder_is_labelled_by_the_next_run(gallery, tmp_path, monkeypatch, capsys):
    out = tmp_path / "papers"
    assert _run(gallery, out, tag="first", monkeypatch=monkeypatch) == 0
    stale = out / ".reproduce-partial-999999"  # as SIGKILL leaves it: one script done, run.json "running"
    (stale / "p000_01_first").mkdir(parents=True)
    (stale / "p000_01_first" / "p000_01_first.json").write_text((out / "p000_01_first" / "p000_01_first.json")
                                                                 .read_text())
    run = json.loads((out / "run.json").read_text())
    run.update(state="running", planned=list(NAMES), scripts={"p000_01_first": run["scripts"]["p000_01_first"]})
    (stale / "run.json").write_text(json.dumps(run))
    assert _run(gallery, out, "--merge", "--only", "p000_02_second", monkeypatch=monkeypatch) == 0
    assert "a run that was killed" in capsys.readouterr().err
    [partial] = out.glob("interrupted-*")
    assert "**INTERRUPTED**" in (partial / "index.md").read_text() and not stale.exists()


def test_only_names_a_script_of_the_other_paper(gallery, tmp_path, monkeypatch, capsys):
    assert _run(gallery, tmp_path / "p", "paper000", "--only", "p001_01_third", monkeypatch=monkeypatch) == 2
    assert "p001_01_third belong(s) to paper001, not paper000" in capsys.readouterr().err
    assert _run(gallery, tmp_path / "p", "--only", "p000_01_first.py", monkeypatch=monkeypatch) == 0


def test_a_folder_in_use_by_another_run_is_refused(gallery, tmp_path, monkeypatch, capsys):
    out = tmp_path / "papers"
    out.mkdir()
    fd = os.open(out / ".pamjax.lock", os.O_RDWR | os.O_CREAT)
    import fcntl

    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    try:
        assert _run(gallery, out, monkeypatch=monkeypatch) == 2
        assert "in use by another pamjax" in capsys.readouterr().err
    finally:
        os.close(fd)
    assert pathlib.Path(out).is_dir()


def test_a_script_whose_items_have_no_catalogue_entry_is_reported(gallery, tmp_path, monkeypatch, capsys):
    """A new script lists the paper items it computes (COVERS); until the catalogue has entries computed by it, the
    run says so and exits 1 (its results are written all the same)."""
    path = gallery / "p000_01_first.py"
    path.write_text(path.read_text().replace("COVERS = ()", 'COVERS = ("text: creep near the maximum displacement",)'))
    assert _run(gallery, tmp_path / "p", monkeypatch=monkeypatch) == 1
    err = capsys.readouterr().err
    assert ("catalogue: p000_01_first covers 'text: creep near the maximum displacement' but no catalogue entry is "
            "computed by it") in err
    assert (tmp_path / "p" / "index.md").exists()


def test_fits_module_gives_the_package_procedures():
    from pamjax.gallery import fits_module
    from pamjax.gallery.procedures import bench, regulator

    assert fits_module("control") is bench and fits_module("regulator") is regulator
    assert callable(fits_module("control").bench_plant)
    with pytest.raises(Exception, match="no procedures in the package"):
        fits_module("joint")


def test_an_empty_out_is_refused_by_name(gallery, tmp_path, monkeypatch, capsys):
    """`--out ''` (an unset shell variable) would be Path('') == '.': the current folder. Refused by name, nothing
    written, as the other commands' output folders refuse it."""
    monkeypatch.chdir(tmp_path)
    for empty in ("", "  "):
        assert _run(gallery, empty, monkeypatch=monkeypatch) == 2
        assert "the output folder is empty; name one with --out" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gallery"]
