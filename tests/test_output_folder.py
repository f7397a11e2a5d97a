"""The output folder of a command (`pamjax._cli.out.OutputFolder`): what a resumed run and a stopped --overwrite run
leave in it. (The refusals and the locking are in test_cli.py.)"""

import pytest

from pamjax._cli.out import OutputFolder

OUTPUTS = ["trajectory.csv", "trajectory.png"]


def _earlier(out, names):
    out.mkdir()
    for name in names:
        (out / name).write_text("earlier")


def test_a_resumed_run_removes_the_earlier_figure_it_does_not_redraw(tmp_path):
    # `pamjax fit --resume --no-plot`: fit.json and model.json held the resumed fit, fit.png still drew the fit it
    # resumed from (the stale files were removed only with --overwrite, which --resume does not take)
    out = tmp_path / "out"
    _earlier(out, ["fit.json", "checkpoint.npz", "fit.png"])
    outputs = ["fit.json", "checkpoint.npz"]
    with OutputFolder(out, "pamjax fit", outputs, replaceable=outputs, stale=["fit.png"]) as folder:
        folder.write_text("fit.json", "resumed")
    assert (out / "fit.json").read_text() == "resumed" and not (out / "fit.png").exists()


def test_an_overwrite_run_stopped_midway_leaves_no_earlier_file_beside_its_own(tmp_path, capsys):
    # `simulate --overwrite` stopped after writing trajectory.csv left the earlier run's trajectory.png beside it
    # (one folder, two runs' results); stopped before writing anything, the earlier results stay whole
    out = tmp_path / "out"
    _earlier(out, OUTPUTS + ["notes.txt"])
    with pytest.raises(KeyboardInterrupt):
        with OutputFolder(out, "pamjax simulate", OUTPUTS, overwrite=True):
            raise KeyboardInterrupt
    assert all((out / name).read_text() == "earlier" for name in OUTPUTS)
    with pytest.raises(KeyboardInterrupt):
        with OutputFolder(out, "pamjax simulate", OUTPUTS, overwrite=True) as folder:
            folder.write_text("trajectory.csv", "new")
            raise KeyboardInterrupt
    assert (out / "trajectory.csv").read_text() == "new" and not (out / "trajectory.png").exists()
    assert (out / "notes.txt").read_text() == "earlier"  # not a pamjax output: never touched
    said = capsys.readouterr().out
    assert "stopped after writing trajectory.csv" in said and "earlier run's trajectory.png removed" in said
