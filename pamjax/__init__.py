"""pamjax: differentiable simulation and identification of pneumatic artificial muscle systems in JAX."""

from ._errors import PamjaxInputError as PamjaxInputError, PamjaxSolveError as PamjaxSolveError
from ._friction import (
    AbstractFriction as AbstractFriction,
    BristleFriction as BristleFriction,
    CoulombViscousFriction as CoulombViscousFriction,
)
from ._gas import (
    AbstractRestriction as AbstractRestriction,
    Air as Air,
    EllipseRestriction as EllipseRestriction,
    ISO6358Restriction as ISO6358Restriction,
    NozzleRestriction as NozzleRestriction,
    SeriesRestriction as SeriesRestriction,
)
from ._inputs import (
    AbstractSignal as AbstractSignal,
    Constant as Constant,
    Sampled as Sampled,
    Sine as Sine,
    Step as Step,
    Triangle as Triangle,
)
from ._muscle import (
    AbstractForceLaw as AbstractForceLaw,
    AbstractVolume as AbstractVolume,
    ChouHannafordForce as ChouHannafordForce,
    CubicVolume as CubicVolume,
    EndStops as EndStops,
    LinearVolume as LinearVolume,
    Muscle as Muscle,
    PolynomialForce as PolynomialForce,
    TonduLopezForce as TonduLopezForce,
)
from ._simulate import Trajectory as Trajectory, simulate as simulate
from ._system import (
    AbstractSystem as AbstractSystem,
    MuscleState as MuscleState,
    MuscleSystem as MuscleSystem,
    TankState as TankState,
    TankSystem as TankSystem,
)
from ._valve import (
    AbstractValve as AbstractValve,
    AveragedValve as AveragedValve,
    OnOffValve as OnOffValve,
    cycle_averaged_flow as cycle_averaged_flow,
    fit_averaged_valve as fit_averaged_valve,
)
from . import presets as presets

__version__ = "0.1.0"

# --- discrete-time model (paper 000 eq. 17-21) ---
from ._discrete import (  # noqa: E402
    DiscreteTrajectory as DiscreteTrajectory,
    discrete_step as discrete_step,
    simulate_discrete as simulate_discrete,
)

# --- fitting (issue 3): recordings, experiments, fit, synthetic data ---------------------------------------------
from ._experiment import (  # noqa: E402
    Experiment as Experiment,
    ForceMapExperiment as ForceMapExperiment,
    SameSystem as SameSystem,
    TankFromModel as TankFromModel,
)
from ._fit import (  # noqa: E402
    FitResult as FitResult,
    ParameterSpace as ParameterSpace,
    PamjaxIdentifiabilityWarning as PamjaxIdentifiabilityWarning,
    fit as fit,
    parameter_paths as parameter_paths,
)
from ._recording import Recording as Recording  # noqa: E402
from ._synthetic import synthetic_recording as synthetic_recording  # noqa: E402

# --- proportional pressure regulator, linearisation, antagonistic joint (issue 5, paper 001) -----------------------
from ._joint import AntagonisticJoint as AntagonisticJoint, JointState as JointState, VoltagePair as VoltagePair  # noqa: E402
from ._linearise import StateSpace as StateSpace, equilibrium as equilibrium, linearise as linearise  # noqa: E402
from ._regulated import (  # noqa: E402
    RegulatedMuscleState as RegulatedMuscleState,
    RegulatedMuscleSystem as RegulatedMuscleSystem,
    RegulatorSystem as RegulatorSystem,
    muscle_stiffness as muscle_stiffness,
    stiffness_rate as stiffness_rate,
)
from ._regulator import (  # noqa: E402
    AbstractRegulator as AbstractRegulator,
    FeedbackRegulator as FeedbackRegulator,
    ISO6358Regulator as ISO6358Regulator,
    LinearRegulator as LinearRegulator,
    SquareWave as SquareWave,
    VoltageCalibration as VoltageCalibration,
)
from ._tabulated import TabulatedISO6358Restriction as TabulatedISO6358Restriction  # noqa: E402

# --- issue 4: batch sweeps ---
from ._sweep import (  # noqa: E402
    Final as Final,
    Harmonic as Harmonic,
    Mean as Mean,
    SweepResult as SweepResult,
    sweep as sweep,
)
from ._sweep_maps import (  # noqa: E402
    flow_surface as flow_surface,
    frequency_response as frequency_response,
    steady_state_map as steady_state_map,
)
from ._gradcheck import gradient_check as gradient_check  # noqa: E402

# --- closed-loop control (issue 6) ---------------------------------------------------------------------------------
from ._control import (  # noqa: E402
    AbstractController as AbstractController,
    ClosedLoop as ClosedLoop,
    ClosedLoopState as ClosedLoopState,
    ClosedLoopTrajectory as ClosedLoopTrajectory,
    PIController as PIController,
    SlidingModeController as SlidingModeController,
    equivalent_duty as equivalent_duty,
    run_closed_loop as run_closed_loop,
    simulate_closed_loop as simulate_closed_loop,
    tune_controller as tune_controller,
)

# --- antagonistic joint control (issue 6, item 5) ------------------------------------------------------------------
from ._joint_control import (  # noqa: E402
    AntagonisticJointController as AntagonisticJointController,
    GaitAngle as GaitAngle,
    JointControlLoop as JointControlLoop,
    JointControlState as JointControlState,
    JointControlTrajectory as JointControlTrajectory,
    regulated_stiffness as regulated_stiffness,
    run_joint_control as run_joint_control,
    simulate_joint_control as simulate_joint_control,
)
