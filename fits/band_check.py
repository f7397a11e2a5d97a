"""Bands on predictions, checked against the spread of refits: do the linear (delta-method) bands of a fitted
model's predictions say how much those predictions vary from one noisy recording to the next?

The plant: paper 000's MAS-10-300 lifting 9.6 kg through eq. 13's averaged valve (smooth Coulomb friction), recorded
along a 0.5 Hz triangle of duty 0.05…0.95 for 2 s at 50 Hz with 2 kPa and 0.1 mm of noise (the hybrid bench's).
Five parameters are fitted from the preset's values ×1.1: v0, k0, F_c, C_f and m4. For each of `--seeds` noise
seeds the recording is drawn, the model fitted, and three predictions of the fitted model made with their bands:

- a trajectory of another run (a 0.3 Hz sine of duty 0.5 ± 0.3 over 4 s): pressure and position
  (`pamjax.prediction_band`, forward-mode Jacobian);
- the steady-state map at 7 duties 0.2…0.8 (`pamjax.steady_state_band`, ±1 σ points in one sweep);
- the frequency response duty → position at 0.5, 1 and 2 Hz, gain and phase (`pamjax.frequency_response_band`).

Reported per output: the ratio of the refits' empirical standard deviation to the bands' mean σ (1 if the bands are
right; an empirical σ of N refits scatters by 1/√(2(N−1)), 11 % for 40), its range over times / duties / frequencies,
the coverage of the truth by the 95 % bands (over fits and points), and for the first fit the samples band's σ over
the linear one (200 draws) and the nonlinearity index. Writes `band_check.json` and `band_check.png` (the refits'
predictions, their ±1.96 σ spread and the first fit's band) to `--out`; refuses to replace them unless
`--overwrite`.

    python fits/band_check.py [--seeds 40] [--out results/band_check] [--overwrite] [--quick]

`--quick`: 8 seeds (unless `--seeds` is given), for a smoke run. `--seeds` must be at least 2: the refits' spread
is a standard deviation over seeds (one refit has none).
"""

import argparse
import pathlib
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax import presets  # noqa: E402
from pamjax.gallery import json_text, refuse_existing  # noqa: E402

FREE = ["muscle.volume_law.v0", "muscle.force_law.k0", "friction.coulomb_force", "friction.viscous_coefficient",
        "valve.coefficients[1,0]"]
NOISE = dict(pressure=2e3, position=1e-4)  # Pa, m: the hybrid bench's (meta.json "noise")
FIT_SIGNAL = pj.Triangle(0.05, 0.95, 0.5)
FIT_TIMES = np.linspace(0.0, 2.0, 101)  # s: 50 Hz
RUN_SIGNAL = pj.Sine(0.5, 0.3, 0.3)
RUN_TIMES = np.linspace(0.0, 4.0, 81)
DUTIES = np.linspace(0.2, 0.8, 7)
FREQUENCIES = np.array([0.5, 1.0, 2.0])
MAP = dict(horizon=3.0, window=0.5, progress=False)
RESPONSE = dict(channels=("position",), settle_periods=2, periods=2, progress=False)


def run_prediction(model):
    traj = pj.simulate(model, RUN_SIGNAL, RUN_TIMES, adjoint="forward", rtol=1e-8, atol=1e-8, throw=False)
    return {"pressure": traj.channel("pressure"), "position": traj.channel("position")}


def fit_one(truth, start, seed):
    rec = pj.synthetic_recording(truth, FIT_SIGNAL, FIT_TIMES, noise=NOISE, seed=seed, name="triangle")
    exp = pj.Experiment(rec, FIT_SIGNAL, channels=["pressure", "position"], scales=NOISE)
    return pj.fit(start, [exp], FREE, progress=False)


def bands_of(res, first):
    """The three bands of one fit (the first fit also checks the linearity)."""
    return dict(run=pj.prediction_band(res, run_prediction, check_linearity=first),
                steady=pj.steady_state_band(res, DUTIES, **MAP),
                bode=pj.frequency_response_band(res, FREQUENCIES, **RESPONSE))


def truth_of(truth):
    steady = pj.steady_state_map(truth, DUTIES, **MAP)
    bode = pj.frequency_response(truth, FREQUENCIES, **RESPONSE)
    return dict(run={k: np.asarray(v) for k, v in run_prediction(truth).items()},
                steady={"pressure": np.asarray(steady["pressure"]), "position": np.asarray(steady["position"])},
                bode={"position_gain": bode["position"]["gain"], "position_phase": bode["position"]["phase"]})


def compare(bands, truths):
    """Per prediction and output: the refit spread against the bands, and the coverage of the truth."""
    out = {}
    for kind in ("run", "steady", "bode"):
        for name, true in truths[kind].items():
            pred = np.array([b[kind].prediction[name] for b in bands])
            std = np.array([b[kind].std[name] for b in bands])
            lower = np.array([b[kind].lower[name] for b in bands])
            upper = np.array([b[kind].upper[name] for b in bands])
            live = std.mean(axis=0) > 1e-9 * np.max(np.abs(pred))  # the run's start is known exactly
            ratio = pred.std(axis=0, ddof=1)[live] / std.mean(axis=0)[live]
            inside = (true >= lower) & (true <= upper)
            out[f"{kind}/{name}"] = dict(ratio_median=float(np.median(ratio)), ratio_min=float(ratio.min()),
                                         ratio_max=float(ratio.max()), coverage=float(inside[:, live].mean()),
                                         band_sigma_median=float(np.median(std.mean(axis=0)[live])))
    return out


def plot(path, bands, truths):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    panels = (("run", "position", RUN_TIMES, 1e3, "t [s]", "position [mm]"),
              ("steady", "position", DUTIES, 1e3, "duty", "steady position [mm]"),
              ("bode", "position_phase", FREQUENCIES, 1.0, "frequency [Hz]", "phase duty → position [deg]"))
    for ax, (kind, name, x, scale, xlabel, ylabel) in zip(axes, panels):
        pred = np.array([b[kind].prediction[name] for b in bands])
        centre = truths[kind][name]
        spread = 1.96 * pred.std(axis=0, ddof=1)
        first = bands[0][kind]
        ax.fill_between(x, (first.lower[name] - centre) * scale, (first.upper[name] - centre) * scale, alpha=0.3,
                        label="95 % band of fit 1 (linear)")
        ax.plot(x, -spread * scale, "k--", lw=0.8, label="±1.96 × spread of the refits")
        ax.plot(x, spread * scale, "k--", lw=0.8)
        for p in pred:
            ax.plot(x, (p - centre) * scale, color="C1", lw=0.4, alpha=0.5)
        ax.set(xlabel=xlabel, ylabel=f"{ylabel}, minus the truth")
        if kind == "bode":
            ax.set_xscale("log")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Bands on predictions against {len(bands)} refits over noise seeds (orange: each refit)")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=None, help="noise seeds, refits (default 40; 8 with --quick)")
    parser.add_argument("--out", default="results/band_check")
    parser.add_argument("--overwrite", action="store_true")
    parser.add_argument("--quick", action="store_true", help="8 seeds unless --seeds is given (a smoke run)")
    args = parser.parse_args()
    seeds = args.seeds if args.seeds is not None else 8 if args.quick else 40
    if seeds < 2:  # one refit gives a NaN spread (std with ddof=1), none a ValueError after the work
        parser.error(f"--seeds must be at least 2 (the refits' spread is a standard deviation over seeds), got {seeds}")
    out = pathlib.Path(args.out)
    refuse_existing("band_check.py", [out / "band_check.json", out / "band_check.png"], args.overwrite)
    out.mkdir(parents=True, exist_ok=True)
    truth = presets.mas10_system(valve="averaged")
    space = pj.ParameterSpace(truth, FREE)
    start = space.with_values(np.asarray(space.initial_values()) * 1.1)
    t0 = time.perf_counter()
    bands, fits = [], []
    for seed in range(seeds):
        res = fit_one(truth, start, seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pj.PamjaxBandWarning)  # a chance mismatch flag; counted below
            bands.append(bands_of(res, seed == 0))
        fits.append(dict(seed=seed, status=res.status, mismatch=res.mismatch,
                         relative_se=dict(zip(res.labels, np.divide(res.standard_errors, res.values).tolist()))))
        print(f"seed {seed}: {res.status}, {time.perf_counter() - t0:.0f} s", flush=True)
    truths = truth_of(truth)
    report = compare(bands, truths)
    first = fit_one(truth, start, 0)
    samples = pj.prediction_band(first, run_prediction, method="samples", samples=200)
    live = RUN_TIMES > 0.2
    summary = dict(
        seeds=seeds, free=FREE, converged=sum(f["status"] == "converged" for f in fits),
        mismatch_flags=sum(f["mismatch"] for f in fits), relative_se_fit0=fits[0]["relative_se"],
        compare=report, nonlinearity_fit0={f"{kind}/{c}": v for kind in ("run", "steady", "bode")
                                           for c, v in bands[0][kind].nonlinearity.items()},
        samples_over_linear_fit0={c: [float(np.min(samples.std[c][live] / bands[0]["run"].std[c][live])),
                                      float(np.max(samples.std[c][live] / bands[0]["run"].std[c][live]))]
                                  for c in ("pressure", "position")},
        wall_s=time.perf_counter() - t0)
    (out / "band_check.json").write_text(json_text(summary, indent=1))
    plot(out / "band_check.png", bands, truths)
    for key, row in report.items():
        print(f"{key:24s} refit σ / band σ: median {row['ratio_median']:.3f} ({row['ratio_min']:.3f}…"
              f"{row['ratio_max']:.3f}), coverage {row['coverage']:.3f}")
    print(f"nonlinearity (fit 1): {summary['nonlinearity_fit0']}")
    print(f"samples σ / linear σ (fit 1, run): {summary['samples_over_linear_fit0']}")
    print(f"{summary['converged']}/{seeds} converged, {summary['mismatch_flags']} mismatch flags; "
          f"{summary['wall_s']:.0f} s; wrote {out / 'band_check.json'}, {out / 'band_check.png'}")


if __name__ == "__main__":
    main()
