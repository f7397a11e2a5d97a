"""`pamjax fit`'s figure (`pamjax/_cli/fit_figure.py`) and the process that draws it (`pamjax/_cli/figures.py`): laid
out with the data while the fit runs (`prepare`), then finished with the models; the file is the one drawn at once,
pixel for pixel, whether prepared, prepared for other data, or drawn without a process."""

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib import image  # noqa: E402

from pamjax._cli import figures, fit_figure  # noqa: E402


def _columns(seed=0, split=2.0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 5.0, 201)
    cols = []
    for title, channel, unit, scale in (("run: pressure", "pressure", "[Pa abs]", 3e5),
                                        ("run: position", "position", "[m]", 0.02),
                                        ("tank: pressure", "pressure", "[Pa abs]", 5e5)):
        model = scale * (1.0 + 0.3 * np.sin(t))
        cols.append(dict(title=title, channel=channel, unit=unit, t=t,
                         data=model + 0.01 * scale * rng.standard_normal(t.size), model=model, split=split))
    cols[-1]["split"] = None
    return cols


def _without_models(cols):
    return [{k: v for k, v in c.items() if k != "model"} for c in cols]


def _pixels(path):
    return image.imread(path)


def test_a_prepared_figure_is_the_figure_drawn_at_once(tmp_path):
    cols = _columns()
    fit_figure.draw(tmp_path / "once.png", cols)
    prepared = fit_figure.prepare(_without_models(cols))
    assert fit_figure.matches(cols, _without_models(cols))
    fit_figure.draw(tmp_path / "prepared.png", cols, prepared)
    np.testing.assert_array_equal(_pixels(tmp_path / "once.png"), _pixels(tmp_path / "prepared.png"))


def test_matches_tells_other_data_apart():
    cols = _columns()
    other = _columns(seed=1)
    assert not fit_figure.matches(other, _without_models(cols))  # other noise
    assert not fit_figure.matches(cols[:2], _without_models(cols))  # fewer columns
    moved = _columns(split=3.0)
    assert not fit_figure.matches(moved, _without_models(cols))  # another identification | validation split


@pytest.mark.parametrize("prepare_with", ["same data", "other data", "nothing"])
def test_the_figure_process_draws_what_it_is_sent(tmp_path, prepare_with):
    """Through the process `pamjax fit` starts: prepared with the fit's data, with other data (it must not reuse that
    layout) or not at all, the file equals the one drawn here at once."""
    cols = _columns()
    fit_figure.draw(tmp_path / "here.png", cols)
    process = figures.FigureProcess(fit_figure)
    try:
        if prepare_with == "same data":
            process.prepare(_without_models(cols))
        elif prepare_with == "other data":
            process.prepare(_without_models(_columns(seed=3)))
        process.draw(tmp_path / "process.png", cols)
    finally:
        process.close()
    np.testing.assert_array_equal(_pixels(tmp_path / "here.png"), _pixels(tmp_path / "process.png"))


def test_an_error_in_the_process_comes_back_as_its_own_type(tmp_path):
    process = figures.FigureProcess(fit_figure)
    try:
        process.prepare(_without_models(_columns()))
        with pytest.raises(OSError):
            process.draw(tmp_path / "no such folder" / "fig.png", _columns())
    finally:
        process.close()


def test_many_channels_wrap_into_rows_of_panels(tmp_path):
    """A rig's ten compared channels: rows of at most `PER_ROW` columns (not one strip 40 inches wide), each
    column's residual panel right under its data panel, every panel inside the figure and none overlapping."""
    cols = [dict(c, title=f"{c['title']} {i}") for i in range(3) for c in _columns(seed=i)][:7]
    fit_figure.draw(tmp_path / "seven.png", cols)
    fit_figure.draw(tmp_path / "three.png", cols[:3])
    seven, three = _pixels(tmp_path / "seven.png"), _pixels(tmp_path / "three.png")
    assert seven.shape[1] == round(4 * fit_figure.PER_ROW * fit_figure.DPI) and seven.shape[0] == 2 * three.shape[0]
    fig, axes = fit_figure.prepare(_without_models(cols))
    boxes = [[ax.get_position() for ax in axes[:, j]] for j in range(len(cols))]
    for j, (upper, lower) in enumerate(boxes):
        assert lower.y1 < upper.y0 and abs(lower.x0 - upper.x0) < 1e-12, j  # the residuals right under the data
        assert all(0.0 < v < 1.0 for b in (upper, lower) for v in (b.x0, b.x1, b.y0, b.y1)), j
    second = fit_figure.PER_ROW  # the first column of the second row: under the first row's panels
    assert boxes[second][0].y1 < boxes[0][1].y0 and abs(boxes[second][0].x0 - boxes[0][0].x0) < 1e-12
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 2 * len(cols)
    for a in range(len(visible)):
        for b in range(a):
            p, q = visible[a].get_position(), visible[b].get_position()
            assert p.x1 <= q.x0 or q.x1 <= p.x0 or p.y1 <= q.y0 or q.y1 <= p.y0  # no two panels overlap
