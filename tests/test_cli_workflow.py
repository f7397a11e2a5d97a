"""The command line end to end, on a small problem (a 0.5 s tank charge, one free eq. 13 term, a few seconds):
`pamjax fit` writes its result, the complete fitted model and a checkpoint; Ctrl-C keeps the checkpoint and says how to
resume; `--resume` ends where an uninterrupted fit ends, bitwise; a resume of a changed config is refused naming what
changed; the fitted model starts a new fit (`[model] file`) and a simulation (`pamjax simulate`)."""

import json
import os
import re
import signal
import subprocess
import sys
import textwrap

import jax.tree_util as jtu
import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._cli.main import main

CONFIG = """
    [model]
    preset = "mas10_tank_system"
    options = {{ valve = "averaged" }}
    set = {{ "valve.coefficients[1,0]" = {start} }}
    [fit]
    free = ["valve.coefficients[1,0]"]
    max_steps = 20
    [[experiment]]
    name = "tank"
    file = "tank.csv"
    signal = {{ kind = "Constant", value = 0.5 }}
    channels = ["pressure"]
    scales = {{ pressure = 2e3 }}
"""


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A folder with the recording (pressure [Pa abs], command) and a fit config."""
    root = tmp_path_factory.mktemp("cli")
    truth = presets.mas10_tank_system("averaged")
    rec = pamjax.synthetic_recording(truth, pamjax.Constant(0.5), np.linspace(0.0, 0.5, 26),
                                     noise=dict(pressure=2e3), seed=0, name="tank")
    rec.to_csv(root / "tank.csv")
    (root / "fit.toml").write_text(textwrap.dedent(CONFIG.format(start=1.5e-3)))
    return root


@pytest.fixture(scope="module")
def reference(folder):
    """An uninterrupted `pamjax fit`: its fit.json."""
    assert main(["fit", str(folder / "fit.toml"), "--out", str(folder / "reference"), "--quiet", "--no-plot"]) == 0
    return json.loads((folder / "reference" / "fit.json").read_text())


def _fields(result):
    return {k: v for k, v in result.items() if k not in ("fit_s", "compile_s")}


def test_fit_writes_result_complete_model_and_checkpoint(folder, reference, capsys):
    out = folder / "reference"
    assert reference["converged"] and (out / "checkpoint.npz").exists()
    model = pamjax.load_model(out / "model.json")
    assert float(model.valve.coefficients[1, 0]) == reference["values"][0]  # the fitted value, bitwise
    start = presets.mas10_tank_system("averaged")
    assert jtu.tree_structure(model) == jtu.tree_structure(start)  # the whole model, not only the free value
    np.testing.assert_array_equal(model.valve.coefficients[0], start.valve.coefficients[0])
    doc = json.loads((out / "model.json").read_text())
    assert doc["parameters"]["volume"]["unit"] == "m³" and doc["provenance"]["status"] == "converged"
    # a second run never replaces the results
    before = (out / "fit.json").read_bytes()
    assert main(["fit", str(folder / "fit.toml"), "--out", str(out), "--quiet"]) == 2
    assert re.search(r"fit.json exists; pass --overwrite to replace it", capsys.readouterr().err)
    assert (out / "fit.json").read_bytes() == before


def _interrupting_fit(monkeypatch, after):
    """`pamjax.fit` as the CLI calls it, interrupted (as by Ctrl-C) as iteration `after` reports."""
    real = pamjax.fit

    def fit(*args, progress=True, **kwargs):
        def report(step, cost, step_size, accepted):
            if step == after:
                raise KeyboardInterrupt

        return real(*args, progress=report, **kwargs)

    monkeypatch.setattr(pamjax, "fit", fit)


def test_interrupted_fit_keeps_its_checkpoint_and_resumes_bitwise(folder, reference, monkeypatch, capsys):
    last = reference["iterations"]  # interrupted as its last iteration reports: the checkpoint holds the one before
    assert last >= 2  # from 235 times the final cost, one step does not converge
    out, config = folder / "interrupted", str(folder / "fit.toml")
    _interrupting_fit(monkeypatch, after=last)
    assert main(["fit", config, "--out", str(out), "--quiet"]) == 130
    printed = capsys.readouterr()
    assert "Traceback" not in printed.out + printed.err
    line = next(ln for ln in printed.err.splitlines() if "interrupted" in ln)
    assert re.search(rf"checkpoint after iteration {last - 1} \(cost .*\) is kept in .*checkpoint.npz\. Resume with: "
                     rf"pamjax fit {re.escape(config)} --out {re.escape(str(out))} --resume$", line)
    assert (out / "checkpoint.npz").exists() and not (out / "fit.json").exists()
    monkeypatch.undo()
    # without --resume the checkpoint is not silently dropped
    assert main(["fit", config, "--out", str(out), "--quiet"]) == 2
    assert re.search(rf"holds an earlier fit \(checkpointed after iteration {last - 1} \(cost .*\)\); continue it "
                     r"with --resume, or start again with --overwrite", capsys.readouterr().err)
    assert main(["fit", config, "--out", str(out), "--quiet", "--no-plot", "--resume"]) == 0
    resumed = json.loads((out / "fit.json").read_text())
    assert _fields(resumed) == _fields(reference)  # values, cost, iterations, history: bitwise
    # resuming the finished fit again changes nothing and may replace its own results
    assert main(["fit", config, "--out", str(out), "--quiet", "--no-plot", "--resume"]) == 0
    assert _fields(json.loads((out / "fit.json").read_text())) == _fields(reference)


def test_resume_of_a_changed_problem_is_refused_naming_what_changed(folder, reference, capsys):
    out = folder / "reference"  # holds the reference fit's checkpoint
    changed = folder / "changed.toml"
    changed.write_text(textwrap.dedent(CONFIG.format(start=1.6e-3)))  # another start value, same shapes
    assert main(["fit", str(changed), "--out", str(out), "--quiet", "--resume"]) == 2
    assert re.search(r"saved by a different fit: the start model differs in valve\.coefficients",
                     capsys.readouterr().err)
    rec = pamjax.Recording.load(folder / "tank.csv")
    other = pamjax.Recording(rec.t, {"pressure": rec["pressure"] + 1.0, "command": rec["command"]}, name="tank")
    other.to_csv(folder / "other" / "tank.csv")
    (folder / "other" / "fit.toml").write_text(textwrap.dedent(CONFIG.format(start=1.5e-3)))
    assert main(["fit", str(folder / "other" / "fit.toml"), "--out", str(out), "--quiet", "--resume"]) == 2
    assert "experiment 'tank' has other data" in capsys.readouterr().err


def test_the_fitted_model_starts_a_fit_and_a_simulation(folder, reference, capsys):
    (folder / "refit.toml").write_text(textwrap.dedent("""
        [model]
        file = "reference/model.json"    # relative to the config
        [fit]
        free = ["valve.coefficients[1,0]"]
        max_steps = 1
        [[experiment]]
        name = "tank"
        file = "tank.csv"
        signal = { kind = "Constant", value = 0.5 }
        channels = ["pressure"]
        scales = { pressure = 2e3 }
    """))
    assert main(["fit", str(folder / "refit.toml"), "--out", str(folder / "refit"), "--quiet", "--no-plot"]) == 0
    refit = json.loads((folder / "refit" / "fit.json").read_text())
    assert refit["initial_values"] == reference["values"]  # started from the fitted model
    (folder / "sim.toml").write_text(textwrap.dedent("""
        [model]
        file = "reference/model.json"
        [input]
        file = "tank.csv"                # its command drives the model; outputs at its times
    """))
    assert main(["simulate", str(folder / "sim.toml"), "--out", str(folder / "sim")]) == 0
    header = next(ln for ln in (folder / "sim" / "trajectory.csv").read_text().splitlines() if ln[0] != "#")
    assert header == "t [s],command [1],pressure [Pa abs],mass_flow [kg/s]"
    written = pamjax.Recording.load(folder / "sim" / "trajectory.csv")
    rec = pamjax.Recording.load(folder / "tank.csv")
    expected = pamjax.simulate(pamjax.load_model(folder / "reference" / "model.json"),
                               pamjax.Sampled(rec.t, rec["command"]), rec.t)
    np.testing.assert_array_equal(written["pressure"], expected.pressure)
    assert (folder / "sim" / "trajectory.png").stat().st_size > 10_000


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_real_interrupt_during_compilation_exits_cleanly(folder, signum, code):
    # Ctrl-C (or a job scheduler's SIGTERM) from outside, as a user sends it: before the first iteration has been
    # checkpointed there is nothing to resume, and the line says so; no traceback; the folder is unlocked.
    out = folder / f"signal{code}"
    proc = subprocess.Popen([sys.executable, "-m", "pamjax", "fit", str(folder / "fit.toml"), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "JAX_PLATFORMS": "cpu"})
    device = proc.stdout.readline()  # where the command runs (docs/cli.md, Device), before any work
    assert device.startswith("pamjax fit: running on"), device + proc.stderr.read()
    first = proc.stdout.readline()  # printed once the folder is held, just before the fit compiles
    assert first.startswith("fitting 1 parameter entries"), first + proc.stderr.read()
    proc.send_signal(signum)
    rest, err = proc.communicate(timeout=300)
    assert proc.returncode == code, rest + err
    assert "Traceback" not in rest + err
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    if (out / "checkpoint.npz").exists():  # the signal came late: the line names the checkpoint instead
        assert f"pamjax fit: {word}; the checkpoint after" in err and "--resume" in err, err
    else:
        assert f"pamjax fit: {word} before the first iteration finished; nothing to resume" in err, err
    assert not (out / ".pamjax.lock").exists()


def _copy_of(out, into):
    import shutil

    shutil.copytree(out, into)
    (into / ".pamjax.lock").unlink(missing_ok=True)
    return into


def test_a_damaged_checkpoint_is_named_and_overwrite_starts_again(folder, reference, capsys):
    # A truncated checkpoint.npz (a full disk, a copy cut short) made every `pamjax fit` into that folder, --overwrite
    # included, an internal error: "BadZipFile: File is not a zip file", status 1, the file not named.
    out, config = _copy_of(folder / "reference", folder / "damaged"), str(folder / "fit.toml")
    checkpoint = out / "checkpoint.npz"
    checkpoint.write_bytes(checkpoint.read_bytes()[:2000])
    for flags in ([], ["--resume"]):
        assert main(["fit", config, "--out", str(out), "--quiet", "--no-plot", *flags]) == 2
        err = capsys.readouterr().err
        assert re.search(rf"{re.escape(str(checkpoint))} is not a readable checkpoint \(BadZipFile: .*\), so no fit "
                         r"can be resumed from it: start again with --overwrite \(which replaces it\)", err), err
    assert main(["fit", config, "--out", str(out), "--quiet", "--no-plot", "--overwrite"]) == 0
    assert _fields(json.loads((out / "fit.json").read_text())) == _fields(reference)
    with np.load(checkpoint) as f:  # replaced by this fit's
        assert int(f["history"][-1][0]) == reference["iterations"]


def test_a_resume_without_a_checkpoint_is_refused_before_the_folder_is_made(folder, monkeypatch, capsys):
    # Refused with status 2, but after creating the output folder (and its parents), left empty.
    def no_fit(*args, **kwargs):
        raise AssertionError("a fit was started")

    monkeypatch.setattr(pamjax, "fit", no_fit)
    out = folder / "never" / "made"
    assert main(["fit", str(folder / "fit.toml"), "--out", str(out), "--resume", "--quiet", "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert f"pamjax fit: error: {out} holds no checkpoint (checkpoint.npz); run without --resume to start the fit" \
        in err, err
    assert not (folder / "never").exists()


def test_a_damaged_staged_start_is_named_on_resume(tmp_path):
    # A truncated staged_start.npz on --resume (was: "BadZipFile: File is not a zip file", status 1).
    from pamjax._cli import fit_start

    path = tmp_path / fit_start.STAGED_START
    np.savez(path, values=np.zeros(3), summary=np.asarray(["stage 1"]), problem=np.asarray("{}"))
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(pamjax.PamjaxInputError, match=r"resume: .*staged_start\.npz is not a readable staged start "
                                                      r"\(BadZipFile: .*\); start again with --overwrite"):
        fit_start.load(path, None, [], [])


def test_an_overwrite_interrupted_before_its_first_checkpoint_offers_no_resume(folder, reference, monkeypatch, capsys):
    # --overwrite interrupted before this run checkpointed anything (was: "the checkpoint after iteration N ... is kept.
    # Resume with: ... --resume", naming the EARLIER run's checkpoint, whose resume is then refused).
    out, config = _copy_of(folder / "reference", folder / "overwritten"), str(folder / "fit.toml")
    before = (out / "checkpoint.npz").read_bytes()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(pamjax, "fit", interrupted)
    assert main(["fit", config, "--out", str(out), "--quiet", "--no-plot", "--overwrite"]) == 130
    err = capsys.readouterr().err
    assert re.search(r"interrupted before the first iteration finished; nothing to resume \(this run checkpointed "
                     rf"nothing; {re.escape(str(out / 'checkpoint.npz'))} is the earlier fit's, left as it was\): run "
                     rf"pamjax fit {re.escape(config)} --out {re.escape(str(out))} --overwrite to start again",
                     err), err
    assert "Resume with" not in err and (out / "checkpoint.npz").read_bytes() == before
