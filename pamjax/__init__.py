"""pamjax: differentiable simulation and identification of pneumatic artificial muscle systems in JAX.

The public names, grouped by concept (`docs/architecture.md` says where each lives and why); bench directories and
bench tests in `pamjax.bench`, runtime knobs in `pamjax.runtime`, unchecked traceable cores in `pamjax.unchecked`."""
# ruff: noqa: E402, I001  (the XLA CPU setting is applied before the submodules are imported; groups by concept)

# First, before anything can initialise JAX's backend: XLA's CPU setting for small while loops (see _core.xla_cpu).
from ._core.xla_cpu import apply as _apply_xla_cpu_setting

_apply_xla_cpu_setting()

from ._core.deprecation import moved as _moved
from ._core.metadata import version as _version

__version__ = _version()  # from the package metadata (pyproject.toml)

# --- errors and warnings -------------------------------------------------------------------------------------------
from ._core.errors import PamjaxInputError as PamjaxInputError, PamjaxSolveError as PamjaxSolveError
from ._fit.parameters import PamjaxIdentifiabilityWarning as PamjaxIdentifiabilityWarning
from ._fit.recording import PamjaxDataWarning as PamjaxDataWarning

# --- physics: gas and restrictions, valves, regulators, muscles, friction, signals ---------------------------------
from ._physics.friction import (
    AbstractFriction as AbstractFriction, BristleFriction as BristleFriction,
    CoulombViscousFriction as CoulombViscousFriction, KarnoppFriction as KarnoppFriction,
)
from ._physics.hysteresis import BoucWenFriction as BoucWenFriction
from ._physics.gas import (
    AbstractRestriction as AbstractRestriction, Air as Air, EllipseRestriction as EllipseRestriction,
    ISO6358Restriction as ISO6358Restriction, NozzleRestriction as NozzleRestriction,
    PorousRestriction as PorousRestriction, SeriesRestriction as SeriesRestriction,
)
from ._physics.muscle import (
    AbstractForceLaw as AbstractForceLaw, AbstractMuscle as AbstractMuscle, AbstractVolume as AbstractVolume,
    BraidVolume as BraidVolume, ChouHannafordForce as ChouHannafordForce, CubicVolume as CubicVolume,
    EndStops as EndStops, LinearVolume as LinearVolume, Muscle as Muscle, PolynomialForce as PolynomialForce,
    TonduLopezForce as TonduLopezForce,
)
from ._physics.regulator import (
    AbstractRegulator as AbstractRegulator, FeedbackRegulator as FeedbackRegulator,
    ISO6358Regulator as ISO6358Regulator, ISO6358RegulatorState as ISO6358RegulatorState,
    LinearRegulator as LinearRegulator, PressureHysteresis as PressureHysteresis,
    VoltageCalibration as VoltageCalibration, vppm_regulator as vppm_regulator,
)
from ._physics.signals import (
    AbstractSignal as AbstractSignal, Constant as Constant, Sampled as Sampled, Sine as Sine, SquareWave as SquareWave,
    Step as Step, Triangle as Triangle,
)
from ._physics.tabulated import TabulatedISO6358Restriction as TabulatedISO6358Restriction
from ._physics.valves.averaged import (
    AveragedValve as AveragedValve, cycle_averaged_flow as cycle_averaged_flow,
    fit_averaged_valve as fit_averaged_valve,
)
from ._physics.valves.base import (
    AbstractControlElement as AbstractControlElement, AbstractSwitchingValve as AbstractSwitchingValve,
    AbstractValve as AbstractValve,
)
from ._physics.valves.onoff import OnOffValve as OnOffValve

# --- systems: the vector fields over named states ------------------------------------------------------------------
from ._systems.base import AbstractMuscleSystem as AbstractMuscleSystem, AbstractSystem as AbstractSystem
from ._systems.joint import AntagonisticJoint as AntagonisticJoint, JointState as JointState, VoltagePair as VoltagePair
from ._systems.joint_control import (
    AntagonisticJointController as AntagonisticJointController, GaitAngle as GaitAngle,
    JointControlLoop as JointControlLoop, JointControlState as JointControlState,
    regulated_stiffness as regulated_stiffness,
)
from ._systems.muscle import MuscleState as MuscleState, MuscleSystem as MuscleSystem
from ._systems.regulated import (
    RegulatedMuscleState as RegulatedMuscleState, RegulatedMuscleSystem as RegulatedMuscleSystem,
    RegulatorSystem as RegulatorSystem, muscle_stiffness as muscle_stiffness, stiffness_rate as stiffness_rate,
)
from ._systems.tank import TankState as TankState, TankSystem as TankSystem

# --- solving: simulate, the discrete-time model, linearisation, gradient checks (unchecked cores: pamjax.unchecked) -
from ._solve.discrete import DiscreteTrajectory as DiscreteTrajectory, simulate_discrete as simulate_discrete
from ._solve.gradcheck import gradient_check as gradient_check
from ._solve.linearise import StateSpace as StateSpace, equilibrium as equilibrium, linearise as linearise
from ._solve.simulate import Trajectory as Trajectory, simulate as simulate

# --- fitting: recordings, experiments, parameters, fit, model files, designs (bench directories: pamjax.bench) ----
from ._identifiability.design import DesignResult as DesignResult, design_experiment as design_experiment
from ._identifiability.design_result import PamjaxDesignWarning as PamjaxDesignWarning
from ._fit.experiment import AbstractExperiment as AbstractExperiment, Experiment as Experiment
from ._fit.builds import PayloadFromModel as PayloadFromModel, SameSystem as SameSystem, TankFromModel as TankFromModel
from ._fit.fit import FitResult as FitResult, evaluate as evaluate, fit as fit
from ._files.model_file import load_model as load_model, save_model as save_model
from ._fit.multistart import (
    FleetResult as FleetResult, MultistartResult as MultistartResult, fit_fleet as fit_fleet, multistart as multistart,
)
from ._fit.measurement import Measurement as Measurement
from ._fit.parameters import ParameterSpace as ParameterSpace, parameter_paths as parameter_paths
from ._fit.predictions import predictions as predictions
from ._identifiability.profile import (
    LikelihoodProfile as LikelihoodProfile, ProfileResult as ProfileResult, profile_likelihood as profile_likelihood,
)
from ._identifiability.lowest import ProfiledFit as ProfiledFit, profile_to_minimum as profile_to_minimum
from ._fit.recording import Recording as Recording
from ._fit.rig import (
    Rig as Rig, RunConditions as RunConditions, Sensors as Sensors, StartState as StartState,
    nuisance_report as nuisance_report,
)
from ._fit.staged import StagedStart as StagedStart, staged_start as staged_start
from ._fit.synthetic import synthetic_recording as synthetic_recording

# --- sweeps --------------------------------------------------------------------------------------------------------
from ._sweep.maps import (
    flow_surface as flow_surface, frequency_response as frequency_response, steady_state_map as steady_state_map,
)
from ._sweep.reductions import (
    AbstractReduction as AbstractReduction, FinalValue as FinalValue, FourierCoefficient as FourierCoefficient,
    WindowMean as WindowMean,
)
from ._sweep.result import SweepResult as SweepResult, merge_sweep_shards as merge_sweep_shards
from ._sweep.sweep import sweep as sweep

# --- bands on predictions: a fit's covariance carried to trajectories, maps and frequency responses ----------------
from ._bands.band import PredictionBand as PredictionBand, prediction_band as prediction_band
from ._bands.maps import (
    flow_surface_band as flow_surface_band, frequency_response_band as frequency_response_band,
    steady_state_band as steady_state_band,
)
from ._bands.uncertainty import (
    FitUncertainty as FitUncertainty, PamjaxBandWarning as PamjaxBandWarning, read_uncertainty as read_uncertainty,
)

# --- control: sampled-data controllers, closed loops, joint control ------------------------------------------------
from ._control.closed_loop import (
    ClosedLoop as ClosedLoop, ClosedLoopState as ClosedLoopState, ClosedLoopTrajectory as ClosedLoopTrajectory,
    simulate_closed_loop as simulate_closed_loop,
)
from ._control.controllers import (
    AbstractController as AbstractController, PIController as PIController,
    SlidingModeController as SlidingModeController, equivalent_duty as equivalent_duty,
)
from ._control.estimator import (
    ExtendedKalmanFilter as ExtendedKalmanFilter, KalmanState as KalmanState, LoopSensors as LoopSensors,
)
from ._control.joint import (
    JointControlTrajectory as JointControlTrajectory, simulate_joint_control as simulate_joint_control,
)
from ._control.pid import PIDController as PIDController
from ._control.tuning import tune_controller as tune_controller

# --- the papers' plants, every number sourced; unit constants; the sub-namespaces ----------------------------------
from . import bench as bench, presets as presets, runtime as runtime, unchecked as unchecked, units as units

# imported on first use: diffrax (~0.4 s) and optimistix (~0.3 s), which a fit on fixed grids from the cache never needs
_LAZY = {"Rodas5": "._solve.rodas_solver", "LevenbergMarquardt": "._fit.solver", "levenberg_marquardt": "._fit.drive"}


def __getattr__(name):
    """`_LAZY` names on first use; moved or renamed names for one release, warned (`_core/deprecation.py`)."""
    if name in _LAZY:
        return getattr(__import__(_LAZY[name][1:], globals(), level=1, fromlist=[name]), name)
    return _moved(__name__, name)


def __dir__():
    return sorted({*globals(), *_LAZY})
