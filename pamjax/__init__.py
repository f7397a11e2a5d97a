"""pamjax: differentiable simulation and identification of pneumatic artificial muscle systems in JAX.

The public names, grouped by concept; `docs/architecture.md` says where each lives and why.
"""
# ruff: noqa: E402  (the XLA CPU setting must be applied before the submodules are imported)

# First, before anything can initialise JAX's backend: XLA's CPU setting for small while loops (see _core.xla_cpu).
from ._core.xla_cpu import apply as _apply_xla_cpu_setting

_apply_xla_cpu_setting()

from ._core.metadata import version as _version

__version__ = _version()  # from the package metadata (pyproject.toml)

# isort: split
# --- errors and warnings -------------------------------------------------------------------------------------------
from ._core.distributed import PamjaxDistributedError as PamjaxDistributedError
from ._core.errors import PamjaxInputError as PamjaxInputError, PamjaxSolveError as PamjaxSolveError
from ._fit.parameters import PamjaxIdentifiabilityWarning as PamjaxIdentifiabilityWarning
from ._fit.recording import PamjaxDataWarning as PamjaxDataWarning

# isort: split
# --- physics: gas and restrictions, valves, regulators, muscles, friction, signals ---------------------------------
from ._physics.friction import (
    AbstractFriction as AbstractFriction,
    BristleFriction as BristleFriction,
    CoulombViscousFriction as CoulombViscousFriction,
    KarnoppFriction as KarnoppFriction,
)
from ._physics.gas import (
    AbstractRestriction as AbstractRestriction,
    Air as Air,
    EllipseRestriction as EllipseRestriction,
    ISO6358Restriction as ISO6358Restriction,
    NozzleRestriction as NozzleRestriction,
    PorousRestriction as PorousRestriction,
    SeriesRestriction as SeriesRestriction,
)
from ._physics.hysteresis import BoucWenFriction as BoucWenFriction
from ._physics.muscle import (
    AbstractForceLaw as AbstractForceLaw,
    AbstractVolume as AbstractVolume,
    BraidVolume as BraidVolume,
    ChouHannafordForce as ChouHannafordForce,
    CubicVolume as CubicVolume,
    EndStops as EndStops,
    LinearVolume as LinearVolume,
    Muscle as Muscle,
    PolynomialForce as PolynomialForce,
    TonduLopezForce as TonduLopezForce,
)
from ._physics.regulator import (
    AbstractRegulator as AbstractRegulator,
    FeedbackRegulator as FeedbackRegulator,
    ISO6358Regulator as ISO6358Regulator,
    ISO6358RegulatorState as ISO6358RegulatorState,
    LinearRegulator as LinearRegulator,
    PressureHysteresis as PressureHysteresis,
    VoltageCalibration as VoltageCalibration,
    vppm_regulator as vppm_regulator,
)
from ._physics.signals import (
    AbstractSignal as AbstractSignal,
    Constant as Constant,
    Sampled as Sampled,
    Sine as Sine,
    SquareWave as SquareWave,
    Step as Step,
    Triangle as Triangle,
)
from ._physics.tabulated import TabulatedISO6358Restriction as TabulatedISO6358Restriction
from ._physics.valves.averaged import (
    AveragedValve as AveragedValve,
    cycle_averaged_flow as cycle_averaged_flow,
    fit_averaged_valve as fit_averaged_valve,
)
from ._physics.valves.base import (
    AbstractControlElement as AbstractControlElement,
    AbstractSwitchingValve as AbstractSwitchingValve,
    AbstractValve as AbstractValve,
)
from ._physics.valves.onoff import OnOffValve as OnOffValve

# isort: split
# --- systems: the vector fields over named states ------------------------------------------------------------------
from ._systems.base import AbstractSystem as AbstractSystem
from ._systems.joint import (
    AntagonisticJoint as AntagonisticJoint,
    JointState as JointState,
    VoltagePair as VoltagePair,
)
from ._systems.joint_control import (
    AntagonisticJointController as AntagonisticJointController,
    GaitAngle as GaitAngle,
    JointControlLoop as JointControlLoop,
    JointControlState as JointControlState,
    regulated_stiffness as regulated_stiffness,
)
from ._systems.muscle import MuscleState as MuscleState, MuscleSystem as MuscleSystem
from ._systems.regulated import (
    RegulatedMuscleState as RegulatedMuscleState,
    RegulatedMuscleSystem as RegulatedMuscleSystem,
    RegulatorSystem as RegulatorSystem,
    muscle_stiffness as muscle_stiffness,
    stiffness_rate as stiffness_rate,
)
from ._systems.tank import TankState as TankState, TankSystem as TankSystem

# isort: split
# --- solving: simulate, the discrete-time model, linearisation, gradient checks ------------------------------------
from ._solve.discrete import (
    DiscreteTrajectory as DiscreteTrajectory,
    discrete_step as discrete_step,
    simulate_discrete as simulate_discrete,
)
from ._solve.gradcheck import gradient_check as gradient_check
from ._solve.linearise import StateSpace as StateSpace, equilibrium as equilibrium, linearise as linearise
from ._solve.simulate import (
    Trajectory as Trajectory,
    default_solver as default_solver,
    simulate as simulate,
    solve as solve,
)
from ._solve.synchronous import num_periods as num_periods

# isort: split
# --- fitting: recordings, experiments, parameters, fit, bench directories, model files ------------------------------
from ._fit.bench import (
    BENCH_NUISANCES as BENCH_NUISANCES,
    BENCH_PARAMETERS as BENCH_PARAMETERS,
    FITTED_KINDS as FITTED_KINDS,
    Bench as Bench,
    bench_nuisance as bench_nuisance,
    bench_rmse as bench_rmse,
    bench_values as bench_values,
    load_bench as load_bench,
    nuisance_table as nuisance_table,
)
from ._fit.bench_tests import (
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
from ._fit.design import DesignResult as DesignResult, design as design
from ._fit.experiment import (
    AbstractExperiment as AbstractExperiment,
    Experiment as Experiment,
    SameSystem as SameSystem,
    TankFromModel as TankFromModel,
)
from ._fit.fit import FitResult as FitResult, evaluate as evaluate, fit as fit
from ._fit.lm import levenberg_marquardt as levenberg_marquardt
from ._fit.model_io import load_model as load_model, save_model as save_model
from ._fit.multistart import (
    FleetResult as FleetResult,
    MultistartResult as MultistartResult,
    fit_fleet as fit_fleet,
    multistart as multistart,
)
from ._fit.parameters import ParameterSpace as ParameterSpace, parameter_paths as parameter_paths
from ._fit.predictions import predictions as predictions
from ._fit.profile import Profile as Profile, ProfileResult as ProfileResult, profile as profile
from ._fit.recording import Recording as Recording
from ._fit.rig import (
    Rig as Rig,
    RunConditions as RunConditions,
    Sensors as Sensors,
    StartState as StartState,
    nuisance_report as nuisance_report,
)
from ._fit.staged import StagedStart as StagedStart, staged_start as staged_start
from ._fit.synthetic import synthetic_recording as synthetic_recording

# isort: split
# --- sweeps --------------------------------------------------------------------------------------------------------
from ._sweep.maps import (
    flow_surface as flow_surface,
    frequency_response as frequency_response,
    steady_state_map as steady_state_map,
)
from ._sweep.reductions import (
    AbstractReduction as AbstractReduction,
    Final as Final,
    Harmonic as Harmonic,
    Mean as Mean,
)
from ._sweep.result import SweepResult as SweepResult, merge_sweep_shards as merge_sweep_shards
from ._sweep.sweep import sweep as sweep

# isort: split
# --- bands on predictions: a fit's covariance carried to trajectories, maps and frequency responses ----------------
from ._bands.band import PredictionBand as PredictionBand, prediction_band as prediction_band
from ._bands.maps import (
    flow_surface_band as flow_surface_band,
    frequency_response_band as frequency_response_band,
    steady_state_band as steady_state_band,
)
from ._bands.uncertainty import (
    FitUncertainty as FitUncertainty,
    PamjaxBandWarning as PamjaxBandWarning,
    read_uncertainty as read_uncertainty,
)

# isort: split
# --- control: sampled-data controllers, closed loops, joint control ------------------------------------------------
from ._control.closed_loop import (
    ClosedLoop as ClosedLoop,
    ClosedLoopState as ClosedLoopState,
    ClosedLoopTrajectory as ClosedLoopTrajectory,
    run_closed_loop as run_closed_loop,
    simulate_closed_loop as simulate_closed_loop,
)
from ._control.controllers import (
    AbstractController as AbstractController,
    PIController as PIController,
    SlidingModeController as SlidingModeController,
    equivalent_duty as equivalent_duty,
)
from ._control.estimator import (
    ExtendedKalmanFilter as ExtendedKalmanFilter,
    KalmanState as KalmanState,
    LoopSensors as LoopSensors,
)
from ._control.joint import (
    JointControlTrajectory as JointControlTrajectory,
    run_joint_control as run_joint_control,
    simulate_joint_control as simulate_joint_control,
)
from ._control.pid import PIDController as PIDController
from ._control.tuning import tune_controller as tune_controller

# isort: split
# --- runtime: processes, compilation cache, XLA CPU setting --------------------------------------------------------
from ._core.cache import CompileStats as CompileStats, enable_compilation_cache as enable_compilation_cache
from ._core.distributed import ProcessInfo as ProcessInfo, initialize_distributed as initialize_distributed
from ._core.xla_cpu import prefer_fast_compilation as prefer_fast_compilation, xla_cpu_status as xla_cpu_status

# isort: split
# --- the papers' plants, every number sourced; unit constants --------------------------------------------------------
from . import presets as presets, units as units


def __getattr__(name):
    """`pamjax.Rodas5`, imported on first use: its module imports diffrax (~0.4 s), which a fit on the fixed grids
    loaded from the cache never needs."""
    if name == "Rodas5":
        from ._solve.rodas_solver import Rodas5

        return Rodas5
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted({*globals(), "Rodas5"})
