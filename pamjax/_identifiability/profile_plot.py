"""The figure of a `ProfileResult`: every profile with its threshold, the fitted value and the linearised curve."""

import math

import numpy as np


def plot_profiles(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(result.profiles)
    cols = min(4, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.0 * rows), squeeze=False)
    for ax, p in zip(axes.ravel(), result.profiles):
        v, d = np.asarray(p.values), np.asarray(p.delta)
        ax.plot(v, d, "o-", ms=3, lw=1, label="profile")
        se = (p.linearised[1] - p.linearised[0]) / (2 * math.sqrt(result.threshold))
        if np.isfinite(se) and se > 0:
            grid = np.linspace(v.min(), v.max(), 200)
            ax.plot(grid, ((grid - p.value) / se) ** 2, "--", color="C7", lw=0.8, label="linearised")
        ax.axhline(result.threshold, color="C3", lw=0.8, label=f"{result.level:.0%} threshold")
        ax.axvline(p.value, color="k", lw=0.5)
        lo, hi = p.interval
        ax.axvspan(max(lo, v.min()), min(hi, v.max()), color="C2", alpha=0.12, label="LR interval")
        ax.set_ylim(-0.05 * result.threshold, 2.0 * result.threshold)
        ax.set_title(f"{p.label.split('.')[-1]}\n{p.verdict}", fontsize=8)
        ax.set_xlabel(p.label, fontsize=7)
        ax.set_ylabel("Δχ²", fontsize=7)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
