"""`pamjax fit`'s figure (data vs model per experiment and channel, residuals below), drawn by `draw(path, columns)`.

Also a script: `pamjax._cli.figures` runs this file in a Python process of its own when a fit starts, so that
importing matplotlib and its first drawing (fonts, ticks, the PNG writer: ~1 s of Python) happen on another core
while the fit runs; the script then waits for one pickled request on stdin (`{"path": ..., "columns": [...]}`), draws
it and answers one line on stdout: "ok", or the error's type and message. The request may come after a first one,
`{"prepare": columns}` (the columns without their models, sent when the fit starts): that figure is then laid out
and drawn once while the fit runs, and the request only adds the models to it (`prepare`). It imports neither
pamjax nor JAX (as a script it is not part of the package), only NumPy and matplotlib.

`columns`: one dict per compared channel, with `title`, `channel`, `unit`, `t`, `data`, `model` (arrays over the
samples) and `split` (the identification | validation boundary [s], or None).
"""

import io
import os
import pickle
import sys

import numpy as np


def _figure(**kwargs):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure  # no pyplot: no global figure registry, the same drawing

    return Figure(**kwargs)


DPI = 110


def draw(path, columns, prepared=None):
    """Write the figure of `columns` (see the module docstring) to `path` as PNG; `prepared`: what `prepare` made of
    the same columns without their models, if anything (the figure is the same either way)."""
    fig, axes = prepared if prepared is not None else _layout(columns)
    for j, col in enumerate(columns):
        t, data, model = (np.asarray(col[k]) for k in ("t", "data", "model"))
        axes[0, j].plot(t, model, "k-", lw=0.8, label="model")
        if col["split"] is not None:
            for ax in axes[:, j]:
                ax.axvline(col["split"], color="C3", lw=0.8, ls="--")
        axes[1, j].plot(t, model - data, lw=0.8)
    if any(col["split"] is not None for col in columns):
        axes[0, 0].plot([], [], color="C3", lw=0.8, ls="--", label="identification | validation")
    axes[0, 0].legend(fontsize=7)
    fig.savefig(path, dpi=DPI, format="png")


def prepare(columns):
    """The figure of `columns` so far as it does not depend on the models (axes, data, titles, labels), drawn once
    in memory: the axes' ticks are made and the labels' text laid out before the fit ends, so that `draw` (given
    this) only adds the models and writes the file (~0.06 s sooner after the fit)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig, axes = _layout(columns)
    FigureCanvasAgg(fig).draw()
    return fig, axes


def matches(columns, prepared_columns):
    """Whether `columns` are those `prepare` was given (titles, units, times, data, splits), models aside."""
    keys = ("title", "channel", "unit", "split")
    return len(columns) == len(prepared_columns) and all(
        all(a[k] == b[k] for k in keys) and all(np.array_equal(a[k], b[k]) for k in ("t", "data"))
        for a, b in zip(columns, prepared_columns))


PER_ROW = 5  # compared channels side by side at most; more wrap into further rows (a 10-channel rig: 2 rows of 5)


def _layout(columns):
    """(figure, axes) with each column's data, title and axis labels; `axes[0, j]` and `axes[1, j]` are column j's
    data and residual panels (one above the other), the columns in rows of at most `PER_ROW`."""
    n = len(columns)
    across, rows = min(n, PER_ROW), -(-n // PER_ROW)
    fig = _figure(figsize=(4 * across, 6 * rows), dpi=DPI)
    grid = fig.subplots(2 * rows, across, squeeze=False)
    axes = np.empty((2, n), dtype=object)
    for j in range(n):
        axes[0, j], axes[1, j] = grid[2 * (j // across), j % across], grid[2 * (j // across) + 1, j % across]
        axes[1, j].sharex(axes[0, j])
        axes[0, j].tick_params(labelbottom=False)
    for k in range(n, rows * across):  # the last row's empty places
        grid[2 * (k // across), k % across].set_visible(False)
        grid[2 * (k // across) + 1, k % across].set_visible(False)
    for j, col in enumerate(columns):
        unit = col["unit"]
        axes[0, j].plot(np.asarray(col["t"]), np.asarray(col["data"]), ".", ms=2, label="data")
        axes[0, j].set(title=col["title"], ylabel=f"{col['channel']} {unit}".strip())
        axes[1, j].set(xlabel="t [s]", ylabel=f"model − data {unit.replace(' abs', '')}".strip())
    _margins(fig, across, rows)
    return fig, axes


def _margins(fig, n, rows):
    """Fixed margins in inches, room for six-digit tick labels (pressures in Pa), an axis label and a title: the
    layout `tight_layout` would find for these axes, without its extra drawing pass (a third of the figure's time).
    Between a column's two panels a small gap, between rows of columns room for the residuals' time axis and the
    next title."""
    width, height = fig.get_size_inches()
    left, right, top, bottom, gap_x, gap_y, gap_rows = 0.95, 0.15, 0.35, 0.55, 1.05, 0.2, 0.9  # inches
    axis_w = (width - left - right - (n - 1) * gap_x) / n
    axis_h = (height - top - bottom - rows * gap_y - (rows - 1) * gap_rows) / (2 * rows)
    fig.subplots_adjust(left=left / width, right=1 - right / width, top=1 - top / height, bottom=bottom / height,
                        wspace=gap_x / axis_w, hspace=gap_y / axis_h)
    if rows > 1:  # subplots_adjust spaces every row alike: move each pair of panels to its own place
        for r in range(rows):
            y0 = bottom + (rows - 1 - r) * (2 * axis_h + gap_y + gap_rows)
            for ax in fig.axes:
                spec = ax.get_subplotspec()
                if spec is not None and spec.rowspan.start // 2 == r:
                    upper = spec.rowspan.start % 2 == 0
                    box = ax.get_position()
                    ax.set_position([box.x0, (y0 + (axis_h + gap_y if upper else 0.0)) / height, box.width,
                                     axis_h / height])


def _warm_up():
    """Import matplotlib and draw a small figure of the same kind into memory (fonts, ticks, PNG writer loaded)."""
    t = np.linspace(0.0, 1.0, 5)
    draw(io.BytesIO(), [dict(title="warm-up", channel="pressure", unit="[Pa abs]", t=t, data=t, model=t, split=0.5)])


def _waiting():
    """Whether a request is already waiting on stdin (then it warms matplotlib up itself)."""
    try:
        import select

        return bool(select.select([sys.stdin], [], [], 0)[0])
    except (OSError, ValueError):  # e.g. Windows, where select takes sockets only: warm up as before
        return False


def _serve():
    try:
        import matplotlib.figure  # noqa: F401 - the import first: the longest part, needed either way

        if not _waiting():  # nothing to draw yet: draw a small figure meanwhile (fonts, ticks, the PNG writer)
            _warm_up()
    except Exception:  # noqa: BLE001 - reported when a figure is asked for (e.g. no matplotlib)
        pass
    prepared = None
    try:
        request = pickle.load(sys.stdin.buffer)
        if "prepare" in request:  # the data, sent while the fit runs: its figure laid out now
            try:
                prepared = (request["prepare"], prepare(request["prepare"]))
            except Exception:  # noqa: BLE001 - drawn from scratch below (and its error reported then)
                prepared = None
            request = pickle.load(sys.stdin.buffer)
    except (EOFError, pickle.UnpicklingError, KeyboardInterrupt):  # the command ended without a figure
        return
    try:
        columns = request["columns"]
        draw(request["path"], columns,
             prepared[1] if prepared is not None and matches(columns, prepared[0]) else None)
        answer = "ok"
    except Exception as err:  # noqa: BLE001 - sent back to the command, which reports it as its own
        answer = f"{type(err).__name__}\t{err}".replace("\n", " ")
    sys.stdout.write(answer + "\n")
    sys.stdout.flush()
    os._exit(0)  # the figure is written: no interpreter teardown for the command to wait for


if __name__ == "__main__":
    _serve()
