"""The top-level names that moved to a sub-namespace or were renamed (issue 31), kept one release as deprecated
aliases: `pamjax.<old>` still resolves, with a `DeprecationWarning` that names the new place."""

import sys
import warnings

# old top-level name → its new place, relative to the package
MOVED = {
    **{name: f"bench.{name}" for name in (
        "BENCH_NUISANCES", "BENCH_PARAMETERS", "FITTED_KINDS", "Bench", "bench_nuisance", "bench_rmse", "bench_values",
        "load_bench", "nuisance_table", "FlowCurveExperiment", "ForceMapExperiment", "FrictionCurveExperiment",
        "LoopForceMapExperiment", "constant_velocity_point", "flow_curve", "loop_average", "steady_friction_force")},
    **{name: f"runtime.{name}" for name in (
        "CompileStats", "enable_compilation_cache", "PamjaxDistributedError", "ProcessInfo", "initialize_distributed",
        "prefer_fast_compilation", "xla_cpu_status", "select_devices", "DeviceChoice")},
    **{name: f"unchecked.{name}" for name in (
        "solve", "default_solver", "num_periods", "discrete_step", "run_closed_loop", "run_joint_control")},
    # generic names given meaningful ones
    "Final": "FinalValue",  # a sweep reduction: the value at the last output time (not typing.Final)
    "Mean": "WindowMean",  # a sweep reduction: the mean over the last `window` seconds
    "Harmonic": "FourierCoefficient",  # a sweep reduction: the complex Fourier coefficient at the lane's frequency
    "design": "design_experiment",  # designs an experiment's input signal (not a controller, valve or muscle)
    "profile": "profile_likelihood",  # profile likelihoods of fitted parameters (not a run-time profile)
    "Profile": "LikelihoodProfile",  # one parameter's profile likelihood (not a signal or motion profile)
}


def moved(package_name, name):
    """The package's attribute for a deprecated top-level `name`, with a `DeprecationWarning` naming its new place
    (attributed to the line that asked for it); AttributeError for any other name. The package's `__getattr__`."""
    package = sys.modules[package_name]
    if name not in MOVED:
        raise AttributeError(f"module {package.__name__!r} has no attribute {name!r}")
    new = MOVED[name]
    warnings.warn(f"{package.__name__}.{name} is deprecated and will be removed in the next release: use "
                  f"{package.__name__}.{new}", DeprecationWarning, stacklevel=3)
    value = package
    for part in new.split("."):
        value = getattr(value, part)
    return value
