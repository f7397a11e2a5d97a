"""What an `Experiment` drives, built from the model: the model itself (`SameSystem`), a constant-volume tank fed by its
valve (`TankFromModel`: paper 000's valve tests) or the model lifting another payload (`PayloadFromModel`: a run with
weights added or taken off). Each is a callable model → system; `Experiment(build=...)`, `design_experiment(build=...)`
and a bench's meta.json (`tank_volume`, `payload_kg`) use them."""

import equinox as eqx

from .._core.arrays import as_scalar
from .._core.custom_types import RealScalar, RealScalarLike
from .._core.errors import PamjaxInputError, check_positive, concrete_values
from .._core.units import check_setting
from .._papers import paper000
from .._physics.regulator import AbstractRegulator
from .._systems.base import AbstractMuscleSystem, AbstractSystem
from .._systems.regulated import RegulatorSystem
from .._systems.tank import TankSystem
from .parameters import parameter_paths

# The payload `PayloadFromModel.advised` (and the weak-motion warning of a fit, `pamjax._fit.force_balance`) proposes
# for a run that moves, as a share of the force the muscle pulls at zero contraction and supply pressure: half keeps
# the muscle able to lift it over much of its stroke at high duty and unable to hold it on the upper stop at low duty.
# Measured (benchmarks/RESULTS.md, identify, Session 52): one 25 s triangle run with 30 kg (half the MAS-10 preset's
# 577 N) beside E3 and E4 brought all nine stop-resting unseen rigs from 2.6-208 % off to within 0.57 %; the fits'
# own advice there, 24-36 kg, did as well.
PAYLOAD_SHARE = 0.5
# A tank's polytropic index where the model has none of its own: 1.4, adiabatic (paper 000's tank tests, eq. 15).
DEFAULT_TANK_POLYTROPIC_INDEX = paper000.POLYTROPIC_INDEX


class SameSystem(eqx.Module):
    """The model is the system of the experiment."""

    def __call__(self, model):
        return model


def _optional_scalar(value: RealScalarLike | None) -> RealScalar | None:
    """`as_scalar`, None kept (the field's "not given")."""
    return None if value is None else as_scalar(value)


class TankFromModel(eqx.Module):
    """A constant-volume tank of `volume` [m³] fed by the model's valve (paper 000's valve tests), or by its pressure
    regulator (a `RegulatorSystem`: paper 001's tank, its appendix), at the polytropic index `polytropic_index`:
    by default the model's own (its `polytropic_index`: the air is the model's, and so is how it exchanges heat;
    a model set to 1.0 charged its tank at 1.4, 49 kPa high after 0.09 s), 1.4 (`DEFAULT_TANK_POLYTROPIC_INDEX`) for
    a model without one."""

    volume: RealScalar = eqx.field(converter=as_scalar)  # m³
    polytropic_index: RealScalar | None = eqx.field(converter=_optional_scalar, default=None)  # - (None: the model's)

    def __call__(self, model):
        index = self.polytropic_index
        if index is None:  # the model's parameter by the path a fit frees it by (no system contract names it)
            index = (model.polytropic_index if "polytropic_index" in parameter_paths(model)
                     else DEFAULT_TANK_POLYTROPIC_INDEX)
        if isinstance(model.valve, AbstractRegulator):
            return RegulatorSystem(regulator=model.valve, volume=self.volume, air=model.air, polytropic_index=index)
        return TankSystem(valve=model.valve, volume=self.volume, air=model.air, polytropic_index=index)


class PayloadFromModel(eqx.Module):
    """The model's system lifting another payload of `mass` [kg]: a run made with weights added or taken off (a
    bench's `payload_kg`). Every other parameter, the fitted ones included, is the model's."""

    mass: RealScalar = eqx.field(converter=as_scalar)  # kg

    def __check_init__(self):
        check_positive(self.mass, "PayloadFromModel.mass")
        if concrete_values(self.mass) is not None:  # 9600 (grams) lifted 9.6 t; the model's payload_mass refuses it
            check_setting("payload_mass", self.mass, "PayloadFromModel.mass:")

    def __call__(self, model):
        if not isinstance(model, AbstractMuscleSystem):
            raise PamjaxInputError(f"PayloadFromModel: {type(model).__name__} lifts no payload (not a muscle system)")
        return eqx.tree_at(lambda s: s.payload_mass, model, self.mass)

    @classmethod
    def advised(cls, model: AbstractSystem) -> "PayloadFromModel":
        """The payload to record a run with where the model's payload rests on the upper stop (its muscle pulls more
        than the payload weighs there at every pressure, so no duty brings it down): `PAYLOAD_SHARE` (half) of the
        force the model's muscle pulls at zero contraction and its valve's supply pressure, over g. Design at your
        best estimate (the fit that warned), not the datasheet: the advice follows the model's force law."""
        if not isinstance(model, AbstractMuscleSystem):
            raise PamjaxInputError(f"PayloadFromModel.advised: {type(model).__name__} lifts no payload (not a muscle "
                                   "system)")
        force = float(model.muscle.static_force(0.0, model.valve.supply(), model.air))
        if not force > 0:
            raise PamjaxInputError(f"PayloadFromModel.advised: the model's muscle pulls {force:g} N at zero "
                                   "contraction and supply pressure; no payload can be advised from it")
        return cls(PAYLOAD_SHARE * force / float(model.gravity))
