"""The figures of `--band`: each banded quantity drawn with its band shaded, and under it a narrow panel of the band
around the prediction (lower − prediction, upper − prediction, in a unit scaled to it), since a band of a well
fitted model is often thinner than the line that draws the prediction."""

import numpy as np

from .._core.units import ATMOSPHERE

# (factor from SI, unit) per quantity, smallest first: a deviation is drawn in the first unit that keeps it < 1000
UNITS = {
    "pressure": ((1.0, "Pa"), (1e-3, "kPa"), (1e-6, "MPa")),
    "position": ((1e6, "µm"), (1e3, "mm"), (1.0, "m")),
    "force": ((1e3, "mN"), (1.0, "N")),
    "mass_flow": ((1e6, "mg/s"), (1e3, "g/s"), (1.0, "kg/s")),
    "phase": ((1.0, "deg"),),
    "percent": ((100.0, "%"),),
}


def _figure(rows, ratios, width=9):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(rows, 1, figsize=(width, 1.2 + sum(ratios) * 0.9), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": ratios})
    return plt, fig, axes[:, 0]


def _save(plt, fig, path, dpi=110):
    fig.tight_layout()
    fig.savefig(path, dpi=dpi, format="png")
    plt.close(fig)


def shade(ax, x, lower, upper, band, transform=lambda v: v, color="C0", label=True):
    """The band between `lower` and `upper` (after `transform`, the axis' unit) on `ax`."""
    ax.fill_between(x, transform(np.asarray(lower)), transform(np.asarray(upper)), alpha=0.3, lw=0, color=color,
                    label=f"{100 * band.level:g} % band ({band.method})" if label else None)


def deviation(ax, x, prediction, lower, upper, quantity, name, color="C0", relative=False):
    """The band around the prediction on `ax` (lower − prediction … upper − prediction), in the unit of `UNITS`
    that keeps it below 1000; `relative`: as a fraction of the prediction, in %."""
    prediction = np.asarray(prediction)
    lo, hi = np.asarray(lower) - prediction, np.asarray(upper) - prediction
    if relative:
        lo, hi, quantity = lo / np.abs(prediction), hi / np.abs(prediction), "percent"
    top = np.nanmax(np.abs(np.concatenate([np.ravel(lo), np.ravel(hi)]))) if np.any(np.isfinite(lo)) else 0.0
    scale, unit = next(((f, u) for f, u in UNITS[quantity] if top * f < 1000), UNITS[quantity][-1])
    ax.fill_between(x, lo * scale, hi * scale, alpha=0.3, lw=0, color=color)
    ax.axhline(0.0, color=color, lw=0.6)
    ax.set_ylabel(f"{name} band [{unit}]", fontsize=8)
    ax.tick_params(labelsize=7)


def trajectory(path, traj, band, recording=None, title=""):
    """`pamjax simulate --band`: pressure, position and force (those the system has) with the band, each with its
    band-around-the-simulation panel, then the command."""
    panels = [("pressure", 1e-6, "pressure [MPa abs]")]
    if traj.position is not None:
        panels += [("position", 1e3, "position [mm]"), ("force", 1.0, "muscle force [N]")]
    panels = [p for p in panels if p[0] in band.lower]
    plt, fig, axes = _figure(2 * len(panels) + 1, [3, 1] * len(panels) + [2])
    t = np.asarray(traj.t)
    for k, (c, scale, label) in enumerate(panels):
        ax, below = axes[2 * k], axes[2 * k + 1]
        if recording is not None and c in recording.channels:
            ax.plot(recording.t, recording[c] * scale, ".", ms=2, color="0.6", label="recording")
        ax.plot(t, np.asarray(traj.channel(c)) * scale, lw=0.9, label="simulation")
        shade(ax, t, band.lower[c], band.upper[c], band, lambda v, s=scale: v * s)
        ax.set(ylabel=label)
        deviation(below, t, band.prediction[c], band.lower[c], band.upper[c], "force" if c == "force" else c, c)
    axes[-1].plot(t, np.asarray(traj.channel("command")), lw=0.9)
    axes[-1].set(ylabel="command", xlabel="t [s]")
    axes[0].set_title(title, fontsize=9)
    axes[0].legend(fontsize=7)
    _save(plt, fig, path)


def _steady(spec, b):
    _, u, r, command = spec
    names = [c for c in ("pressure", "position") if c in r.channels]
    plt, fig, axes = _figure(2 * len(names), [3, 1] * len(names), width=7)
    for k, c in enumerate(names):
        to = (lambda v: (v - ATMOSPHERE) / 1e6) if c == "pressure" else (lambda v: v * 1e3)
        ax = axes[2 * k]
        ax.plot(u, to(np.asarray(r[c])))
        shade(ax, u, b.lower[c], b.upper[c], b, to)
        ax.set(ylabel="pressure [MPa gauge]" if c == "pressure" else "displacement [mm]")
        deviation(axes[2 * k + 1], u, b.prediction[c], b.lower[c], b.upper[c], c, c)
    for a in axes if command.dead_bands else ():
        a.axvspan(0, 0.1, color="gray", alpha=0.15)
        a.axvspan(0.9, 1.0, color="gray", alpha=0.15)
    axes[0].set_title(f"Steady state against a constant {command.label}, {100 * b.level:g} % band ({b.method})",
                      fontsize=9)
    axes[0].legend(fontsize=7)
    axes[-1].set(xlabel=command.label)
    return plt, fig


def _bode(spec, b):
    _, f, fr, command = spec
    channel = "position" if "position" in fr else "pressure"
    scale, unit = (1e3, "mm") if channel == "position" else (1e-5, "bar")
    gain, phase = f"{channel}_gain", f"{channel}_phase"
    plt, fig, axes = _figure(4, [3, 1, 3, 1], width=7)
    axes[0].loglog(f, fr[channel]["gain"] * scale)
    shade(axes[0], f, b.lower[gain], b.upper[gain], b, lambda v: v * scale)
    axes[0].set(ylabel=f"gain [{unit} per {command.unit}]")
    axes[0].set_title(f"Frequency response: {command.column} → {channel}, {100 * b.level:g} % band ({b.method})",
                      fontsize=9)
    axes[0].legend(fontsize=7)
    deviation(axes[1], f, b.prediction[gain], b.lower[gain], b.upper[gain], "percent", "gain", relative=True)
    axes[2].semilogx(f, fr[channel]["phase"])
    shade(axes[2], f, b.lower[phase], b.upper[phase], b, label=False)
    axes[2].set(ylabel="phase [deg]")
    deviation(axes[3], f, b.prediction[phase], b.lower[phase], b.upper[phase], "phase", "phase")
    axes[-1].set(xlabel="frequency [Hz]")
    return plt, fig


def _surface(spec, b):
    _, u, p, flow, command = spec
    plt, fig, axes = _figure(2, [3, 1.5], width=7)
    for n, j in enumerate(range(0, len(p), max(1, len(p) // 8))):
        color = f"C{n % 10}"
        axes[0].plot(u, flow[:, j] * 1e3, color=color, label=f"p = {(p[j] - ATMOSPHERE) / 1e6:.2f} MPa gauge")
        shade(axes[0], u, b.lower["mass_flow"][:, j], b.upper["mass_flow"][:, j], b, lambda v: v * 1e3, color, False)
        deviation(axes[1], u, b.prediction["mass_flow"][:, j], b.lower["mass_flow"][:, j],
                  b.upper["mass_flow"][:, j], "mass_flow", "flow", color)
    axes[0].set(ylabel="cycle-averaged mass flow [g/s]")
    axes[0].set_title(f"Averaged flow surface (chamber held at p), {100 * b.level:g} % band ({b.method}) shaded",
                      fontsize=9)
    axes[0].legend(fontsize=7)
    axes[-1].set(xlabel=command.label)
    return plt, fig


def _table(spec, columns):
    _, cols, swept = spec
    x_name = next(c for c in cols if c not in swept)
    y_names = [c for c in cols if c not in swept and c != x_name and c != "status"
               and not c.endswith(("_lower", "_upper"))][:2]
    plt, fig, axes = _figure(2 * len(y_names), [3, 1] * len(y_names), width=7)
    keys = list(zip(*(cols[c] for c in swept)))
    for n, point in enumerate(dict.fromkeys(keys)):
        sel = np.array([k == point for k in keys])
        color, x = f"C{n % 10}", cols[x_name][sel]
        for k, y in enumerate(y_names):
            axes[2 * k].plot(x, cols[y][sel], color=color,
                             label=", ".join(f"{c} = {v:g}" for c, v in zip(swept, point)))
            axes[2 * k].set(ylabel=y)
            if f"{y}_lower" in columns:
                lo, hi = columns[f"{y}_lower"][sel], columns[f"{y}_upper"][sel]
                axes[2 * k].fill_between(x, lo, hi, alpha=0.25, lw=0, color=color)
                axes[2 * k + 1].fill_between(x, lo - cols[y][sel], hi - cols[y][sel], alpha=0.3, lw=0, color=color)
                axes[2 * k + 1].set_ylabel(f"{y} band", fontsize=8)
    axes[0].legend(fontsize=7)
    axes[-1].set(xlabel=x_name)
    return plt, fig


def sweep(path, spec, maps, columns):
    """`pamjax sweep --band`: the map of `spec` (as `pamjax._cli.sweep.plot` draws it) with its band, each quantity
    with its band-around-the-prediction panel (a `[sweep] over` grid: one band per grid point, from `columns`)."""
    kind = spec[0]
    plt, fig = {"steady": _steady, "bode": _bode, "surface": _surface}[kind](spec, maps[0]) if kind != "table" \
        else _table(spec, columns)
    _save(plt, fig, path, dpi=120)
