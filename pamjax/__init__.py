"""pamjax: differentiable simulation and identification of pneumatic artificial muscle systems in JAX."""
# ruff: noqa: E402  (the XLA CPU setting must be applied before the submodules are imported)

# First, before anything can initialise JAX's backend: XLA's CPU setting for small while loops (see _xla_cpu).
from ._xla_cpu import apply as _apply_xla_cpu_setting

_apply_xla_cpu_setting()

from . import presets as presets
from ._errors import PamjaxInputError as PamjaxInputError
from ._errors import PamjaxSolveError as PamjaxSolveError
from ._friction import (
    AbstractFriction as AbstractFriction,
)
from ._friction import (
    BristleFriction as BristleFriction,
)
from ._friction import (
    CoulombViscousFriction as CoulombViscousFriction,
)
from ._friction import (
    KarnoppFriction as KarnoppFriction,
)
from ._gas import (
    AbstractRestriction as AbstractRestriction,
)
from ._gas import (
    Air as Air,
)
from ._gas import (
    EllipseRestriction as EllipseRestriction,
)
from ._gas import (
    ISO6358Restriction as ISO6358Restriction,
)
from ._gas import (
    NozzleRestriction as NozzleRestriction,
)
from ._gas import (
    PorousRestriction as PorousRestriction,
)
from ._gas import (
    SeriesRestriction as SeriesRestriction,
)
from ._inputs import (
    AbstractSignal as AbstractSignal,
)
from ._inputs import (
    Constant as Constant,
)
from ._inputs import (
    Sampled as Sampled,
)
from ._inputs import (
    Sine as Sine,
)
from ._inputs import (
    Step as Step,
)
from ._inputs import (
    Triangle as Triangle,
)
from ._muscle import (
    AbstractForceLaw as AbstractForceLaw,
)
from ._muscle import (
    AbstractVolume as AbstractVolume,
)
from ._muscle import (
    BraidVolume as BraidVolume,
)
from ._muscle import (
    ChouHannafordForce as ChouHannafordForce,
)
from ._muscle import (
    CubicVolume as CubicVolume,
)
from ._muscle import (
    EndStops as EndStops,
)
from ._muscle import (
    LinearVolume as LinearVolume,
)
from ._muscle import (
    Muscle as Muscle,
)
from ._muscle import (
    PolynomialForce as PolynomialForce,
)
from ._muscle import (
    TonduLopezForce as TonduLopezForce,
)
from ._rodas import Rodas5 as Rodas5
from ._simulate import Trajectory as Trajectory
from ._simulate import default_solver as default_solver
from ._simulate import simulate as simulate
from ._system import (
    AbstractSystem as AbstractSystem,
)
from ._system import (
    MuscleState as MuscleState,
)
from ._system import (
    MuscleSystem as MuscleSystem,
)
from ._system import (
    TankState as TankState,
)
from ._system import (
    TankSystem as TankSystem,
)
from ._valve import (
    AbstractValve as AbstractValve,
)
from ._valve import (
    AveragedValve as AveragedValve,
)
from ._valve import (
    OnOffValve as OnOffValve,
)
from ._valve import (
    cycle_averaged_flow as cycle_averaged_flow,
)
from ._valve import (
    fit_averaged_valve as fit_averaged_valve,
)

__version__ = "0.1.0"

# --- discrete-time model (paper 000 eq. 17-21) ---
# --- issue 19: bench tests without a time axis (friction curves, flow curves, loop force maps); PID with noise ----
from ._bench import BENCH_PARAMETERS as BENCH_PARAMETERS
from ._bench import FITTED_KINDS as FITTED_KINDS
from ._bench import Bench as Bench
from ._bench import bench_rmse as bench_rmse
from ._bench import bench_values as bench_values
from ._bench import load_bench as load_bench
from ._bench_tests import (  # noqa: E402
    FlowCurveExperiment as FlowCurveExperiment,
)
from ._bench_tests import (
    FrictionCurveExperiment as FrictionCurveExperiment,
)
from ._bench_tests import (
    LoopForceMapExperiment as LoopForceMapExperiment,
)
from ._bench_tests import (
    constant_velocity_point as constant_velocity_point,
)
from ._bench_tests import (
    flow_curve as flow_curve,
)
from ._bench_tests import (
    loop_average as loop_average,
)
from ._bench_tests import (
    steady_friction_force as steady_friction_force,
)
from ._cache import CompileStats as CompileStats
from ._cache import enable_compilation_cache as enable_compilation_cache

# --- closed-loop control (issue 6) ---------------------------------------------------------------------------------
from ._control import (  # noqa: E402
    AbstractController as AbstractController,
)
from ._control import (
    ClosedLoop as ClosedLoop,
)
from ._control import (
    ClosedLoopState as ClosedLoopState,
)
from ._control import (
    ClosedLoopTrajectory as ClosedLoopTrajectory,
)
from ._control import (
    PIController as PIController,
)
from ._control import (
    SlidingModeController as SlidingModeController,
)
from ._control import (
    equivalent_duty as equivalent_duty,
)
from ._control import (
    run_closed_loop as run_closed_loop,
)
from ._control import (
    simulate_closed_loop as simulate_closed_loop,
)
from ._control import (
    tune_controller as tune_controller,
)
from ._design import DesignResult as DesignResult  # noqa: E402
from ._design import design as design
from ._discrete import (  # noqa: E402
    DiscreteTrajectory as DiscreteTrajectory,
)
from ._discrete import (
    discrete_step as discrete_step,
)
from ._discrete import (
    simulate_discrete as simulate_discrete,
)

# --- issue 18: multi-process runs (jax.distributed), multistart and fleet fits ----------------------------------
from ._distributed import PamjaxDistributedError as PamjaxDistributedError  # noqa: E402
from ._distributed import ProcessInfo as ProcessInfo
from ._distributed import initialize_distributed as initialize_distributed

# --- fitting (issue 3): recordings, experiments, fit, synthetic data ---------------------------------------------
from ._experiment import (  # noqa: E402
    Experiment as Experiment,
)
from ._experiment import (
    ForceMapExperiment as ForceMapExperiment,
)
from ._experiment import (
    SameSystem as SameSystem,
)
from ._experiment import (
    TankFromModel as TankFromModel,
)
from ._experiment import predictions as predictions
from ._fit import (  # noqa: E402
    FitResult as FitResult,
)
from ._fit import (
    evaluate as evaluate,
)
from ._fit import (
    fit as fit,
)
from ._gradcheck import gradient_check as gradient_check  # noqa: E402

# --- proportional pressure regulator, linearisation, antagonistic joint (issue 5, paper 001) -----------------------
from ._joint import AntagonisticJoint as AntagonisticJoint  # noqa: E402
from ._joint import JointState as JointState
from ._joint import VoltagePair as VoltagePair

# --- antagonistic joint control (issue 6, item 5) ------------------------------------------------------------------
from ._joint_control import (  # noqa: E402
    AntagonisticJointController as AntagonisticJointController,
)
from ._joint_control import (
    GaitAngle as GaitAngle,
)
from ._joint_control import (
    JointControlLoop as JointControlLoop,
)
from ._joint_control import (
    JointControlState as JointControlState,
)
from ._joint_control import (
    JointControlTrajectory as JointControlTrajectory,
)
from ._joint_control import (
    regulated_stiffness as regulated_stiffness,
)
from ._joint_control import (
    run_joint_control as run_joint_control,
)
from ._joint_control import (
    simulate_joint_control as simulate_joint_control,
)
from ._linearise import StateSpace as StateSpace  # noqa: E402
from ._linearise import equilibrium as equilibrium
from ._linearise import linearise as linearise
from ._lm import levenberg_marquardt as levenberg_marquardt
from ._model_io import load_model as load_model  # noqa: E402
from ._model_io import save_model as save_model
from ._multistart import FleetResult as FleetResult  # noqa: E402
from ._multistart import MultistartResult as MultistartResult
from ._multistart import fit_fleet as fit_fleet
from ._multistart import multistart as multistart
from ._parameters import (
    PamjaxIdentifiabilityWarning as PamjaxIdentifiabilityWarning,
)
from ._parameters import (
    ParameterSpace as ParameterSpace,
)
from ._parameters import (
    parameter_paths as parameter_paths,
)
from ._pid import PIDController as PIDController  # noqa: E402
from ._profile import Profile as Profile  # noqa: E402
from ._profile import ProfileResult as ProfileResult
from ._profile import profile as profile
from ._recording import PamjaxDataWarning as PamjaxDataWarning
from ._recording import Recording as Recording  # noqa: E402
from ._regulated import (  # noqa: E402
    RegulatedMuscleState as RegulatedMuscleState,
)
from ._regulated import (
    RegulatedMuscleSystem as RegulatedMuscleSystem,
)
from ._regulated import (
    RegulatorSystem as RegulatorSystem,
)
from ._regulated import (
    muscle_stiffness as muscle_stiffness,
)
from ._regulated import (
    stiffness_rate as stiffness_rate,
)
from ._regulator import (  # noqa: E402
    AbstractRegulator as AbstractRegulator,
)
from ._regulator import (
    FeedbackRegulator as FeedbackRegulator,
)
from ._regulator import (
    ISO6358Regulator as ISO6358Regulator,
)
from ._regulator import (
    LinearRegulator as LinearRegulator,
)
from ._regulator import (
    SquareWave as SquareWave,
)
from ._regulator import (
    VoltageCalibration as VoltageCalibration,
)

# --- issue 4: batch sweeps ---
from ._sweep import (  # noqa: E402
    Final as Final,
)
from ._sweep import (
    Harmonic as Harmonic,
)
from ._sweep import (
    Mean as Mean,
)
from ._sweep import (
    SweepResult as SweepResult,
)
from ._sweep import merge_sweep_shards as merge_sweep_shards  # noqa: E402
from ._sweep import (
    sweep as sweep,
)
from ._sweep_maps import (  # noqa: E402
    flow_surface as flow_surface,
)
from ._sweep_maps import (
    frequency_response as frequency_response,
)
from ._sweep_maps import (
    steady_state_map as steady_state_map,
)
from ._synthetic import synthetic_recording as synthetic_recording  # noqa: E402
from ._tabulated import TabulatedISO6358Restriction as TabulatedISO6358Restriction  # noqa: E402
from ._xla_cpu import xla_cpu_status as xla_cpu_status  # noqa: E402
