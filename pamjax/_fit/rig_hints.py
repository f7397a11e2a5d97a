"""What a mismatched fit's residuals point to on a real rig: the nuisances a fit without them leaves in its residuals.

A fit of the ideal plant to a rig's recordings ends with residuals that are not noise (`diagnostics.mismatch`), but
"model mismatch" alone sends the user after the model. The residuals of such a fit carry the signature of each
everyday nuisance, measured here from the data, the fitted predictions and the commands, without another solve:

- **an offset at rest**: where a run starts at rest at atmospheric pressure, until its valve first opens (the fitted
  model's pressure first moves), the model IS the atmosphere; the data's mean there is the pressure sensor's offset.
  An offset is the same all through that window; data that rise in its second half (against its first) are a valve
  that opens before the model's, at a lower duty: a switching valve faster than the model's (its thresholds are the
  switching time over the PWM period, paper 000), reported as such; where the data rise at all beyond the noise (3
  standard errors), the offset is read from the first half only: over the whole window, valves 16 % and 1.3 %
  faster than the model's read as "offsets" of 3.7 kPa and 0.6 kPa (benchmarks/RESULTS.md, design);
- **a valve that opens after the model's**: in the first 0.1 s after the model's valve first opens, the data rise
  less than half as much as the model (and by more than 1 kPa): a switching valve slower than the model's, whose
  thresholds sit at a higher duty (no sensor gain, supply pressure or delay of milliseconds does that);
- **a lag between command and response**: data(t) = model(t − d) ≈ model(t) − d ṁ(t), so the residual regressed on
  −ṁ gives the acquisition delay d (pooled over every run and channel, each weighted by its noise), over the
  identification samples only: past a validation split the fitted parameters' own error extrapolates as a residual
  that follows the slope, which the regression's ± (white noise) does not count (the docs' example, the true model
  with a validation fraction of 0.4, seed 26: "the data lead the model by 0.79 ms (± 0.12 ms)" over all samples,
  0.01 ± 0.19 ms over the identification samples). Data that LEAD the model are no acquisition delay (a sensor
  cannot read early): a switching valve that switches faster than the model's does that (or a command logged late,
  or a plant that responds sooner than the model), and where the model has a switching valve the finding names its
  switching delays beside the (then negative) delay;
- **a start that is not at rest**: a run declared at rest whose first 20 ms move, or sit far from the model's rest
  state (a recording started mid-run);
- **a supply pressure the tank runs contradict**: a discharge starts at its supply, so its first samples give that
  run's supply; tank runs whose steady pressures sit on opposite sides of the model cannot share one supply.

Each finding is reported only where it is significant (its estimate several standard errors from 0) and large
enough to matter (beside the bench figures of issue 29: 0.1 ms, 300 Pa, 1 kPa), with the option that frees it.
"""

import numpy as np

from .experiment import Experiment
from .parameters import parameter_paths
from .rig import is_nuisance

FREE_IT = ("free it: fits/joint.py --nuisance, [bench] nuisance = true in a pamjax fit config, or "
           "load_bench(..., nuisance=True) / pamjax.Rig in Python")
_SIGNIFICANT = 5.0  # standard errors
_MIN_DELAY = 1e-4  # s
_RISING = 3.0  # standard errors of a rise at rest beyond which the offset is read from the first half only
_MIN_OFFSET = 300.0  # Pa
_MIN_SUPPLY = 1e3  # Pa
_START_WINDOW = 0.02  # s
_ONSET = 0.1  # s after the model's valve first opens, where a slower valve's data still rest (E3: 0.14 s at 2.4 ms)
_MIN_ONSET = 1e3  # Pa: a rise missing from the data at the valve's opening
_SWITCHING = ("valve.switch_on_delay", "valve.switch_off_delay")  # a switching valve's delays (paper 000: ~2 ms)
_FREE_SWITCHING = ("free its switching delays: \"t_on\", \"t_off\" in a bench's meta.json fitted_keys (fits/joint.py, "
                   "[bench]), or free = [..., \"valve.switch_on_delay\", \"valve.switch_off_delay\"] in Python")


def _switches(model):
    """Whether the fit's plant has a switching valve with switching delays to free."""
    from .rig import split

    plant = split(model, None, None)[0]
    paths = parameter_paths(plant)
    return all(path in paths for path in _SWITCHING)


def _start_pressure(e, system, model, atmosphere):
    """The start pressure [Pa abs] of an experiment's run, without building its start state (no solve)."""
    from .rig import split

    _, _, run = split(model, e.name, e.sensor_group)
    if run is not None and run.start is not None and run.start.pressure is not None:
        return float(run.start.pressure)
    if e.start_at_supply:
        return float(system.valve.supply())
    return float(e.initial["pressure"]) if "pressure" in e.initial else atmosphere


def _moving_start(e, pred, start_pressure):
    """How a run declared at rest visibly does not start so (its first 20 ms move, or its pressure is far from
    the model's start), as a phrase; "" when it may well start at rest."""
    t = np.asarray(e.times)
    head = t <= t[0] + _START_WINDOW
    if np.count_nonzero(head) < 5:
        return ""
    found = []
    x, sigma_x = np.asarray(e.data["position"])[head], e.scales["position"]
    tt = t[head] - t[0]
    speed = np.polyfit(tt, x, 1)[0]
    se = sigma_x / np.sqrt(np.sum((tt - tt.mean()) ** 2))
    if abs(speed) > max(_SIGNIFICANT * se, 5e-3):
        found.append(f"moves at {speed * 1e3:+.1f} mm/s in its first {_START_WINDOW * 1e3:.0f} ms (± {se * 1e3:.1f})")
    if "pressure" in e.channels:
        p, sigma_p = float(np.mean(np.asarray(e.data["pressure"])[head])), e.scales["pressure"]
        if abs(p - start_pressure) > max(10 * sigma_p, 2e4):
            found.append(f"starts at {p / 1e3:.0f} kPa abs where the model starts at {start_pressure / 1e3:.0f}")
    return " and ".join(found)


def nuisance_hints(model, experiments, predictions, labels):
    """Findings (sentences) of what the residuals of a fit point to among a rig's nuisances that `labels` (the
    fitted parameters) do not already free; [] when none is significant."""
    from .rig import split

    freed = {str(label).split("].", 1)[-1].split(".")[-1] for label in labels if is_nuisance(label)}
    # runs whose start state the fit already frees ("runs[NAME].start.position", ...): their moving start is known
    started = {str(label)[5:].split("].start.", 1)[0].strip("'\"") for label in labels  # runs['1']: quoted
               if str(label).startswith("runs[") and "].start." in str(label)}
    exps = [e for e in experiments if isinstance(e, Experiment) and e.name in predictions]
    hints = []
    num = den = 0.0
    rest = np.zeros(7)  # what the runs that start at rest at atmospheric pressure show there (`_at_rest`), summed
    rest_sigma = None
    starts, supplies, steady = [], [], []
    for e in exps:
        plant, _, _ = split(model, e.name, e.sensor_group)
        system = e.system_for(model)
        atmosphere = float(plant.air.atmospheric_pressure)
        start_p = _start_pressure(e, system, model, atmosphere)
        moving = _moving_start(e, predictions[e.name], start_p) if "position" in e.channels else ""
        if moving and not e.start_at_supply:
            starts.append((e.name, moving))
        t = np.asarray(e.times)
        ident = t <= float(e.split_time)  # the lag from the fitted samples only (module docstring)
        for c in e.channels:
            data, pred = np.asarray(e.data[c]), np.asarray(predictions[e.name][c])
            used = (np.asarray(e.weights[c]) > 0) & np.isfinite(pred)
            if np.count_nonzero(used) < 10:
                continue
            sigma, fitted = e.scales[c], used & ident
            if not moving and np.count_nonzero(fitted) >= 10:  # a run that does not start where the model does
                r, slope = (data - pred)[fitted], np.gradient(pred, t)[fitted]  # says nothing about a lag
                num += float(r @ -slope) / sigma**2
                den += float(slope @ slope) / sigma**2
            if c == "pressure":
                if abs(start_p - atmosphere) < 1.0:  # at rest until the model's pressure first moves (the valve opens)
                    rest += _at_rest(t, data, pred, used, atmosphere)
                    rest_sigma = sigma
                if e.start_at_supply:
                    head = used & (t <= t[0] + 0.005)
                    if np.count_nonzero(head) >= 3:
                        supplies.append((e.name, float(np.mean(data[head] - pred[head])), sigma /
                                         np.sqrt(np.count_nonzero(head)), start_p))
                if "position" not in e.channels:  # a tank run's steady end
                    tail = used & (t >= t[0] + 0.8 * (t[-1] - t[0]))
                    steady.append((e.name, float(np.mean(data[tail] - pred[tail])),
                                   sigma / np.sqrt(max(np.count_nonzero(tail), 1))))
    at_rest = _rest_hints(rest, rest_sigma, model, offset_freed="pressure_offset" in freed) if rest[1] and rest[3] \
        else []
    onset = _onset_hint(rest, rest_sigma, model) if rest[6] else []
    if den > 0 and "delay" not in freed:  # whether the valve opens late was checked (rest[6]) and found (onset)
        hints += _lag_hint(num / den, 1.0 / np.sqrt(den), model, None if not rest[6] else bool(onset))
    hints += at_rest + onset
    for name, finding in starts:
        if name not in started:
            hints.append(f"a start that is not at rest: {name} {finding} (a recording started mid-run?): mark it "
                         f"\"init\": \"unknown\" in meta.json (if it is not already: it is then fitted as if at "
                         f"rest until its start is freed) and {FREE_IT} (start)")
    if "supply_pressure" not in freed:
        off = [(n, d, se, p0) for n, d, se, p0 in supplies if abs(d) > max(_SIGNIFICANT * se, _MIN_SUPPLY)]
        if off:
            runs = ", ".join(f"{n} about {(p0 + d) / 1e3:.1f} kPa abs ({d / 1e3:+.1f} kPa)" for n, d, _, p0 in off)
            hints.append(f"a supply pressure the tank runs contradict: discharges start at their supply pressure, and "
                         f"these start away from the model's ({off[0][3] / 1e3:.1f} kPa abs): {runs}; {FREE_IT} "
                         "(supply_pressure, per run)")
        signs = {np.sign(d) for _, d, se in steady if abs(d) > max(_SIGNIFICANT * se, _MIN_SUPPLY)}
        if len(signs) > 1 and not off:
            spread = ", ".join(f"{n} {d / 1e3:+.1f}" for n, d, _ in steady)
            hints.append(f"a supply pressure the tank runs contradict: their steady pressures sit on both sides of the "
                         f"model (data − model over their last 20 %, kPa: {spread}), which one supply pressure cannot "
                         f"give; {FREE_IT} (supply_pressure, per run)")
    return hints


def _lag_hint(d, se, model, opens_late=None):
    """The lag finding for a pooled lag `d` [s] (positive: the data lag the model) of standard error `se`;
    `opens_late`: whether the valve was found to open after the model's (None: not checked, no run at rest)."""
    if abs(d) <= max(_SIGNIFICANT * se, _MIN_DELAY):
        return []
    found = (f"a lag between command and response: the data {'lag' if d > 0 else 'lead'} the model by "
             f"{abs(d) * 1e3:.2f} ms (± {se * 1e3:.2g} ms; residuals regressed on the model's slope): ")
    if d < 0 and _switches(model):
        found += (f"not an acquisition delay (that makes them lag) but a valve that switches {abs(d) * 1e3:.2f} ms "
                  f"faster than the model's (or a command logged late); {_FREE_SWITCHING}, or a negative delay: ")
    elif _switches(model) and opens_late:  # a slower valve delays both edges alike, and its thresholds show it
        found += (f"a valve that switches up to {abs(d) * 1e3:.2f} ms slower than the model's (it also opens after "
                  f"the model's, below): {_FREE_SWITCHING}; what is left of the lag is an acquisition delay: ")
    elif _switches(model) and opens_late is False:
        found += ("most likely an acquisition delay (a valve slower than the model's would delay the edges alike, "
                  "but it would also open visibly after the model's, which the data do not show; a valve slower by "
                  f"a fraction of a millisecond might not: {_FREE_SWITCHING} if the delay fits poorly); ")
    elif _switches(model):  # no run at rest to tell them apart: both
        found += (f"an acquisition delay, or a valve that switches {abs(d) * 1e3:.2f} ms slower than the model's "
                  f"(both delay every edge alike; a run from rest tells them apart: {_FREE_SWITCHING}); for the "
                  "delay, ")
    elif d < 0:  # no switching valve to blame: the plant or the log's time stamps, not a sensor that reads early
        found += ("not an acquisition delay (that makes them lag) but a command logged late, or a plant that responds "
                  "sooner than the model (a valve that opens faster, a smaller dead band or volume); a negative "
                  "delay: ")
    else:
        found += "an acquisition delay; "
    return [f"{found}{FREE_IT} (delay)"]


def _at_rest(t, data, pred, used, atmosphere):
    """What a run that starts at rest at atmospheric pressure shows, as sums: of data − atmosphere and their counts
    over the first, then the second half of the window before the model's valve opens (its pressure first moves); and
    over the `_ONSET` seconds after it, of data − atmosphere, of model − atmosphere, and their count."""
    out = np.zeros(7)
    moved = np.flatnonzero(np.abs(pred - pred[0]) > 1.0)
    start = moved[0] if moved.size else t.size
    at_rest = np.flatnonzero(used & (np.arange(t.size) < start))
    if at_rest.size >= 6:
        half = at_rest.size // 2
        first, second = data[at_rest[:half]] - atmosphere, data[at_rest[half:]] - atmosphere
        out[:4] = [float(first.sum()), first.size, float(second.sum()), second.size]
    onset = np.flatnonzero(used & (np.arange(t.size) >= start) & (t <= t[min(start, t.size - 1)] + _ONSET))
    if moved.size and onset.size >= 10:
        out[4:] = [float(np.sum(data[onset] - atmosphere)), float(np.sum(pred[onset] - atmosphere)), onset.size]
    return out


def _onset_hint(rest, sigma, model):
    """The finding of the pressure just after the model's valve opens (`_at_rest`'s sums): a valve that opens later."""
    data_rise, model_rise, n = rest[4] / rest[6], rest[5] / rest[6], rest[6]
    se = sigma / np.sqrt(n)
    if model_rise - data_rise > max(_SIGNIFICANT * se, _MIN_ONSET) and data_rise < 0.5 * model_rise:
        return [f"a valve that opens after the model's: in the first {_ONSET * 1e3:.0f} ms after the model's valve "
                f"opens, its pressure rises by {model_rise / 1e3:.1f} kPa on average and the data by "
                f"{data_rise / 1e3:.1f} kPa (± {se / 1e3:.2g}), far less than a sensor's gain, a supply pressure or a "
                "delay of milliseconds explain: the valve opens at a higher duty than the model's threshold"
                + (f" (a switching valve slower than the model's); {_FREE_SWITCHING}" if _switches(model)
                   else "; check the valve's dead band")]
    return []


def _rest_hints(rest, sigma, model, offset_freed):
    """The findings of the pressure at rest (`rest`: `_at_rest`'s sums: data − atmosphere over the first, then the
    second half of each run's window before the model's valve opens; `sigma` the pressure noise)."""
    hints = []
    early, late = rest[0] / rest[1], rest[2] / rest[3]
    rise, rise_se = late - early, sigma * np.sqrt(1.0 / rest[1] + 1.0 / rest[3])
    if rise > max(_SIGNIFICANT * rise_se, _MIN_OFFSET):
        hints.append(f"a valve that opens before the model's: where the model rests at atmospheric pressure (its valve "
                     f"still shut), the data rise by {rise:+.0f} Pa (± {rise_se:.0f} Pa) from the first half of that "
                     "time to the second, which no sensor offset does: the valve opens at a lower duty than the "
                     "model's threshold" + (f" (a switching valve faster than the model's); {_FREE_SWITCHING}"
                                            if _switches(model) else "; check the valve's dead band"))
    # the offset over the whole window; over its first half only where the data rise within it (a valve that opens
    # early shows at the window's end) beyond what noise gives a constant offset (3 standard errors)
    total, n = (rest[0], rest[1]) if rise > _RISING * rise_se else (rest[0] + rest[2], rest[1] + rest[3])
    offset, se = total / n, sigma / np.sqrt(n)
    if not offset_freed and abs(offset) > max(_SIGNIFICANT * se, _MIN_OFFSET):
        hints.append(f"an offset at rest: before the valve first opens, where the model is at atmospheric pressure, "
                     f"the pressure reads {offset:+.0f} Pa (± {se:.0f} Pa over {n:.0f} samples): a pressure sensor "
                     f"offset; {FREE_IT} (pressure_offset, pressure_gain)")
    return hints
