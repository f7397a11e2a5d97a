"""pamjax: differentiable simulation and identification of pneumatic artificial muscle systems in JAX."""
# ruff: noqa: E402  (the XLA CPU setting must be applied before the submodules are imported)

# First, before anything can initialise JAX's backend: XLA's CPU setting for small while loops (see _xla_cpu).
from ._core.xla_cpu import apply as _apply_xla_cpu_setting

_apply_xla_cpu_setting()

from . import presets as presets
from ._core.errors import PamjaxInputError as PamjaxInputError
from ._core.errors import PamjaxSolveError as PamjaxSolveError
from ._physics.friction import (
    AbstractFriction as AbstractFriction,
)
from ._physics.friction import (
    BristleFriction as BristleFriction,
)
from ._physics.friction import (
    CoulombViscousFriction as CoulombViscousFriction,
)
from ._physics.friction import (
    KarnoppFriction as KarnoppFriction,
)
from ._physics.gas import (
    AbstractRestriction as AbstractRestriction,
)
from ._physics.gas import (
    Air as Air,
)
from ._physics.gas import (
    EllipseRestriction as EllipseRestriction,
)
from ._physics.gas import (
    ISO6358Restriction as ISO6358Restriction,
)
from ._physics.gas import (
    NozzleRestriction as NozzleRestriction,
)
from ._physics.gas import (
    PorousRestriction as PorousRestriction,
)
from ._physics.gas import (
    SeriesRestriction as SeriesRestriction,
)
from ._physics.muscle import (
    AbstractForceLaw as AbstractForceLaw,
)
from ._physics.muscle import (
    AbstractVolume as AbstractVolume,
)
from ._physics.muscle import (
    BraidVolume as BraidVolume,
)
from ._physics.muscle import (
    ChouHannafordForce as ChouHannafordForce,
)
from ._physics.muscle import (
    CubicVolume as CubicVolume,
)
from ._physics.muscle import (
    EndStops as EndStops,
)
from ._physics.muscle import (
    LinearVolume as LinearVolume,
)
from ._physics.muscle import (
    Muscle as Muscle,
)
from ._physics.muscle import (
    PolynomialForce as PolynomialForce,
)
from ._physics.muscle import (
    TonduLopezForce as TonduLopezForce,
)
from ._physics.signals import (
    AbstractSignal as AbstractSignal,
)
from ._physics.signals import (
    Constant as Constant,
)
from ._physics.signals import (
    Sampled as Sampled,
)
from ._physics.signals import (
    Sine as Sine,
)
from ._physics.signals import (
    Step as Step,
)
from ._physics.signals import (
    Triangle as Triangle,
)
from ._physics.valve import (
    AbstractValve as AbstractValve,
)
from ._physics.valve import (
    AveragedValve as AveragedValve,
)
from ._physics.valve import (
    OnOffValve as OnOffValve,
)
from ._physics.valve import (
    cycle_averaged_flow as cycle_averaged_flow,
)
from ._physics.valve import (
    fit_averaged_valve as fit_averaged_valve,
)
from ._solve.rodas import Rodas5 as Rodas5
from ._solve.simulate import Trajectory as Trajectory
from ._solve.simulate import default_solver as default_solver
from ._solve.simulate import simulate as simulate
from ._systems.muscle import (
    AbstractSystem as AbstractSystem,
)
from ._systems.muscle import (
    MuscleState as MuscleState,
)
from ._systems.muscle import (
    MuscleSystem as MuscleSystem,
)
from ._systems.muscle import (
    TankState as TankState,
)
from ._systems.muscle import (
    TankSystem as TankSystem,
)

__version__ = "0.1.0"

# --- discrete-time model (paper 000 eq. 17-21) ---
# --- issue 19: bench tests without a time axis (friction curves, flow curves, loop force maps); PID with noise ----
# --- closed-loop control (issue 6) ---------------------------------------------------------------------------------
from ._control.closed_loop import (  # noqa: E402
    AbstractController as AbstractController,
)
from ._control.closed_loop import (
    ClosedLoop as ClosedLoop,
)
from ._control.closed_loop import (
    ClosedLoopState as ClosedLoopState,
)
from ._control.closed_loop import (
    ClosedLoopTrajectory as ClosedLoopTrajectory,
)
from ._control.closed_loop import (
    PIController as PIController,
)
from ._control.closed_loop import (
    SlidingModeController as SlidingModeController,
)
from ._control.closed_loop import (
    equivalent_duty as equivalent_duty,
)
from ._control.closed_loop import (
    run_closed_loop as run_closed_loop,
)
from ._control.closed_loop import (
    simulate_closed_loop as simulate_closed_loop,
)
from ._control.closed_loop import (
    tune_controller as tune_controller,
)
from ._control.pid import PIDController as PIDController  # noqa: E402
from ._core.cache import CompileStats as CompileStats
from ._core.cache import enable_compilation_cache as enable_compilation_cache

# --- issue 18: multi-process runs (jax.distributed), multistart and fleet fits ----------------------------------
from ._core.distributed import PamjaxDistributedError as PamjaxDistributedError  # noqa: E402
from ._core.distributed import ProcessInfo as ProcessInfo
from ._core.distributed import initialize_distributed as initialize_distributed
from ._core.xla_cpu import xla_cpu_status as xla_cpu_status  # noqa: E402
from ._fit.bench import BENCH_PARAMETERS as BENCH_PARAMETERS
from ._fit.bench import FITTED_KINDS as FITTED_KINDS
from ._fit.bench import Bench as Bench
from ._fit.bench import bench_rmse as bench_rmse
from ._fit.bench import bench_values as bench_values
from ._fit.bench import load_bench as load_bench
from ._fit.bench_tests import (  # noqa: E402
    FlowCurveExperiment as FlowCurveExperiment,
)
from ._fit.bench_tests import (
    FrictionCurveExperiment as FrictionCurveExperiment,
)
from ._fit.bench_tests import (
    LoopForceMapExperiment as LoopForceMapExperiment,
)
from ._fit.bench_tests import (
    constant_velocity_point as constant_velocity_point,
)
from ._fit.bench_tests import (
    flow_curve as flow_curve,
)
from ._fit.bench_tests import (
    loop_average as loop_average,
)
from ._fit.bench_tests import (
    steady_friction_force as steady_friction_force,
)

# --- fitting (issue 3): recordings, experiments, fit, synthetic data ---------------------------------------------
from ._fit.experiment import (  # noqa: E402
    Experiment as Experiment,
)
from ._fit.experiment import (
    ForceMapExperiment as ForceMapExperiment,
)
from ._fit.experiment import (
    SameSystem as SameSystem,
)
from ._fit.experiment import (
    TankFromModel as TankFromModel,
)
from ._fit.experiment import predictions as predictions
from ._fit.fit import (  # noqa: E402
    FitResult as FitResult,
)
from ._fit.fit import (
    evaluate as evaluate,
)
from ._fit.fit import (
    fit as fit,
)
from ._fit.model_io import load_model as load_model  # noqa: E402
from ._fit.model_io import save_model as save_model
from ._fit.multistart import FleetResult as FleetResult  # noqa: E402
from ._fit.multistart import MultistartResult as MultistartResult
from ._fit.multistart import fit_fleet as fit_fleet
from ._fit.multistart import multistart as multistart
from ._fit.parameters import (
    PamjaxIdentifiabilityWarning as PamjaxIdentifiabilityWarning,
)
from ._fit.parameters import (
    ParameterSpace as ParameterSpace,
)
from ._fit.parameters import (
    parameter_paths as parameter_paths,
)
from ._fit.recording import PamjaxDataWarning as PamjaxDataWarning
from ._fit.recording import Recording as Recording  # noqa: E402
from ._fit.synthetic import synthetic_recording as synthetic_recording  # noqa: E402
from ._physics.regulator import (  # noqa: E402
    AbstractRegulator as AbstractRegulator,
)
from ._physics.regulator import (
    FeedbackRegulator as FeedbackRegulator,
)
from ._physics.regulator import (
    ISO6358Regulator as ISO6358Regulator,
)
from ._physics.regulator import (
    LinearRegulator as LinearRegulator,
)
from ._physics.regulator import (
    SquareWave as SquareWave,
)
from ._physics.regulator import (
    VoltageCalibration as VoltageCalibration,
)
from ._physics.tabulated import TabulatedISO6358Restriction as TabulatedISO6358Restriction  # noqa: E402
from ._solve.discrete import (  # noqa: E402
    DiscreteTrajectory as DiscreteTrajectory,
)
from ._solve.discrete import (
    discrete_step as discrete_step,
)
from ._solve.discrete import (
    simulate_discrete as simulate_discrete,
)
from ._solve.gradcheck import gradient_check as gradient_check  # noqa: E402
from ._solve.linearise import StateSpace as StateSpace  # noqa: E402
from ._solve.linearise import equilibrium as equilibrium
from ._solve.linearise import linearise as linearise
from ._sweep.maps import (  # noqa: E402
    flow_surface as flow_surface,
)
from ._sweep.maps import (
    frequency_response as frequency_response,
)
from ._sweep.maps import (
    steady_state_map as steady_state_map,
)

# --- issue 4: batch sweeps ---
from ._sweep.sweep import (  # noqa: E402
    Final as Final,
)
from ._sweep.sweep import (
    Harmonic as Harmonic,
)
from ._sweep.sweep import (
    Mean as Mean,
)
from ._sweep.sweep import (
    SweepResult as SweepResult,
)
from ._sweep.sweep import merge_sweep_shards as merge_sweep_shards  # noqa: E402
from ._sweep.sweep import (
    sweep as sweep,
)

# --- proportional pressure regulator, linearisation, antagonistic joint (issue 5, paper 001) -----------------------
from ._systems.joint import AntagonisticJoint as AntagonisticJoint  # noqa: E402
from ._systems.joint import JointState as JointState
from ._systems.joint import VoltagePair as VoltagePair

# --- antagonistic joint control (issue 6, item 5) ------------------------------------------------------------------
from ._systems.joint_control import (  # noqa: E402
    AntagonisticJointController as AntagonisticJointController,
)
from ._systems.joint_control import (
    GaitAngle as GaitAngle,
)
from ._systems.joint_control import (
    JointControlLoop as JointControlLoop,
)
from ._systems.joint_control import (
    JointControlState as JointControlState,
)
from ._systems.joint_control import (
    JointControlTrajectory as JointControlTrajectory,
)
from ._systems.joint_control import (
    regulated_stiffness as regulated_stiffness,
)
from ._systems.joint_control import (
    run_joint_control as run_joint_control,
)
from ._systems.joint_control import (
    simulate_joint_control as simulate_joint_control,
)
from ._systems.regulated import (  # noqa: E402
    RegulatedMuscleState as RegulatedMuscleState,
)
from ._systems.regulated import (
    RegulatedMuscleSystem as RegulatedMuscleSystem,
)
from ._systems.regulated import (
    RegulatorSystem as RegulatorSystem,
)
from ._systems.regulated import (
    muscle_stiffness as muscle_stiffness,
)
from ._systems.regulated import (
    stiffness_rate as stiffness_rate,
)
