"""Bench directories and the bench tests without a time axis.

    import pamjax.bench
    from pamjax import presets
    bench = pamjax.bench.load_bench("path/to/bench", presets.mas10_system(valve="pwm", friction="karnopp"))
    result = pamjax.fit(bench.model, bench.experiments, bench.free)
    values, errors = pamjax.bench.bench_values(result, bench.fitted_keys)   # in the bench's own parameter names

`load_bench` reads a directory in the layout of `pamjax/data/hybrid-reference-bench` (docs/fitting.md); the bench
tests (friction curves, ISO 6358 flow curves, static and loop force maps) are experiments `pamjax.fit` takes beside
`pamjax.Experiment`, each with the reduction that turns a raw bench record into its data points (docs/papers.md).
"""

from ._bench.load import (
    BENCH_NUISANCES as BENCH_NUISANCES,
    BENCH_PARAMETERS as BENCH_PARAMETERS,
    CALIBRATION_NAME as CALIBRATION_NAME,
    FITTED_KINDS as FITTED_KINDS,
    Bench as Bench,
    load_bench as load_bench,
)
from ._bench.report import (
    bench_key as bench_key,
    bench_nuisance as bench_nuisance,
    bench_rmse as bench_rmse,
    bench_values as bench_values,
    fitted_labels as fitted_labels,
    nuisance_table as nuisance_table,
)
from ._fit.static_experiments import (
    FlowCurveExperiment as FlowCurveExperiment,
    ForceMapExperiment as ForceMapExperiment,
    FrictionCurveExperiment as FrictionCurveExperiment,
    HysteresisLoopExperiment as HysteresisLoopExperiment,
    LoopForceMapExperiment as LoopForceMapExperiment,
    constant_velocity_point as constant_velocity_point,
    flow_curve as flow_curve,
    loop_average as loop_average,
    path_friction_force as path_friction_force,
    steady_friction_force as steady_friction_force,
)
