"""The figure of a `DesignResult`: the designed duty, the predicted run against its limits, and the predicted
standard errors against the baseline's and the prior experiments' alone (and, for a design over a spread, at each of
its points)."""

import numpy as np

from .design_result import short_label


def plot_design(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pred = result.prediction or {}
    cons = result.constraints
    stroke = pred.get("position") is not None  # no position panel for a system without one (a tank test)
    ratios = [1, 1, 1, 1.3] if stroke else [1, 1, 1.3]
    fig, panels = plt.subplots(len(ratios), 1, figsize=(11, 2.5 * sum(ratios)), gridspec_kw=dict(height_ratios=ratios))
    axes = list(panels) if stroke else [panels[0], None, *panels[1:]]
    axes[0].step(result.times, result.duty, where="post", lw=0.7)
    for b in cons.get("duty_limits", cons["duty_band"]):
        axes[0].axhline(b, color="C3", lw=0.8, ls="--")
    for b in cons.get("switching_thresholds") or []:
        axes[0].axhline(b, color="0.4", lw=0.8, ls=":")
    optimal = (f"{result.criterion}-optimal" if len(result.subset) == len(result.labels)
               else f"{result.criterion}_s-optimal (on {len(result.subset)} of {len(result.labels)})")
    axes[0].set(ylabel="duty [-]", title=f"{optimal} PWM duty ({result.parametrisation}), "
                                         f"one value per {1e3 * result.period:g} ms period\n(dashed: the duties "
                                         "allowed; dotted: the valve's switching thresholds)")
    if stroke:
        axes[1].plot(pred["t"], 1e3 * np.asarray(pred["position"]), lw=0.7)
        for b in cons["stroke_limits"] or []:
            axes[1].axhline(1e3 * b, color="C3", lw=0.8, ls="--")
        axes[1].set(ylabel="position [mm]", title="predicted at the design point (dashed: end stops less margin)")
        if pred.get("force") is not None:
            twin = axes[1].twinx()
            twin.plot(pred["t"], np.asarray(pred["force"]), lw=0.5, color="C2")
            if cons.get("min_force") is not None:
                twin.axhline(cons["min_force"], color="C2", lw=0.8, ls="--")
            twin.set_ylabel("eq. 7 force [N] (green; dashed: min_force)", color="C2")
    if pred.get("pressure") is not None:
        axes[2].plot(pred["t"], np.asarray(pred["pressure"]) / 1e5, lw=0.5)
        if cons.get("max_pressure") is not None:
            axes[2].axhline(cons["max_pressure"] / 1e5, color="C3", lw=0.8, ls="--")
        axes[2].set(xlabel="t [s]", ylabel="pressure [bar abs]",
                    title=None if stroke else "predicted at the design point")
    else:
        axes[2].axis("off")
    values = np.abs(np.asarray(result.values))
    k = np.arange(len(result.labels))
    series = [("design", "C0")] + ([("baseline", "C1")] if "baseline" in result.standard_errors else [])
    series.append(("prior", "C7"))
    width = 0.8 / len(series)
    for j, (name, color) in enumerate(series):
        rel = np.asarray(result.standard_errors[name], dtype=float) / np.where(values > 0, values, 1.0)
        rel = np.where(np.isfinite(rel), rel, np.nan)
        axes[3].bar(k + (j - (len(series) - 1) / 2) * width, 100 * rel, width, color=color,
                    label={"prior": "prior experiments alone"}.get(name, name))
    if "target" in result.standard_errors:  # what baseline_margin asks, over the design's bars
        target = np.asarray(result.standard_errors["target"], dtype=float) / np.where(values > 0, values, 1.0)
        axes[3].scatter(k - (len(series) - 1) / 2 * width, 100 * np.where(np.isfinite(target), target, np.nan),
                        marker="_", s=300, color="k", zorder=3, label="target (baseline / baseline_margin)")
    for n, point in enumerate(result.points or []):  # a spread design: each point's own, over the design's bars
        own = np.abs(np.asarray(point["values"]))
        rel = np.asarray(point["standard_errors"]["design"], dtype=float) / np.where(own > 0, own, 1.0)
        axes[3].scatter(k - (len(series) - 1) / 2 * width, 100 * np.where(np.isfinite(rel), rel, np.nan), marker=".",
                        s=25, color="C3", zorder=4, label="design at the spread's points" if n == 0 else None)
    if any(np.isfinite(b.get_height()) and b.get_height() > 0 for b in axes[3].patches):
        axes[3].set_yscale("log")
    else:  # nothing determined: no bar to draw on a log scale
        axes[3].text(0.5, 0.5, "no parameter determined (infinite standard errors)", transform=axes[3].transAxes,
                     ha="center", va="center")
    short = [short_label(lbl) for lbl in result.labels]
    axes[3].set_xticks(k, short, rotation=45, ha="right", fontsize=8)
    axes[3].set(ylabel="predicted standard error [% of value]")
    axes[3].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
