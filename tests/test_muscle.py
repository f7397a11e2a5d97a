"""Muscle force laws (paper 000 eq. 5, 6, 7), volumes (eq. 14, paper 001 eq. 4), slack, end stops."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import P_ATM, np_chou_hannaford, np_eq7_force, np_tondu_lopez, softplus

import pamjax
from pamjax import presets

AIR = pamjax.Air()
XS = np.linspace(-0.02, 0.075, 20)
PS = np.array([P_ATM, 2e5, 4e5, 7.01325e5])


def test_eq7_matches_oracle_with_gauge_pressure():
    muscle = presets.mas10_muscle()
    a = presets.MAS10_MAX_FORCE_COEFFICIENTS
    for x in XS:
        for p in PS:
            expected = np_eq7_force(x, p - P_ATM, a, presets.MAS10_K0, presets.MAS10_K1, presets.MAS10_K2)
            got = float(muscle.static_force(jnp.asarray(x), jnp.asarray(p), AIR))
            assert got == pytest.approx(expected, rel=1e-12, abs=1e-9)
            assert float(muscle.force(jnp.asarray(x), jnp.asarray(p), AIR)) == pytest.approx(
                softplus(expected, 1.0), rel=1e-12
            )
    # At p_max (0.6 MPa gauge) eq. 7 reduces to F_max(x); at x = 0 that is the datasheet's 630 N.
    assert float(muscle.static_force(0.0, 6e5 + P_ATM, AIR)) == pytest.approx(630.0, rel=1e-12)


def test_chou_hannaford_eq5_and_virtual_work():
    law = pamjax.ChouHannafordForce(strand_length=0.35, turns=3.0, nominal_length=0.3)
    for x in XS:
        assert float(law.static_force(x, 3e5)) == pytest.approx(np_chou_hannaford(x, 3e5, 0.35, 3.0, 0.3), rel=1e-12)

    # Paper 000 eq. 4: F = −p dV/dL for the braided cylinder V(L) = b³ (cosθ − cos³θ)/(4π n²), cosθ = L/b.
    def volume(length):
        c = length / 0.35
        return 0.35**3 * (c - c**3) / (4 * jnp.pi * 3.0**2)

    for x in (0.0, 0.03, 0.06):
        f_vw = -3e5 * jax.grad(volume)(jnp.asarray(0.3 - x))
        assert float(law.static_force(x, 3e5)) == pytest.approx(float(f_vw), rel=1e-12)


def test_tondu_lopez_eq6():
    law = pamjax.TonduLopezForce(radius=5e-3, braid_angle=0.4, nominal_length=0.3, correction=1.25)
    for x in XS:
        assert float(law.static_force(x, 4e5)) == pytest.approx(np_tondu_lopez(x, 4e5, 5e-3, 0.4, 0.3, 1.25), rel=1e-12)
    # At zero contraction (Tondu & Lopez): F = π r0² p (3 cos²θ0 − 1)/sin²θ0.
    f0 = np.pi * 25e-6 * 4e5 * (3 * np.cos(0.4) ** 2 - 1) / np.sin(0.4) ** 2
    assert float(law.static_force(0.0, 4e5)) == pytest.approx(f0, rel=1e-12)


def test_volumes_and_their_slopes():
    lin = pamjax.LinearVolume(2.4e-5, 4e-4)
    cub = pamjax.CubicVolume(jnp.asarray(presets.DMSP40_VOLUME_CUBIC), 0.4)
    d, c, b, a = presets.DMSP40_VOLUME_CUBIC
    for x in (-0.01, 0.0, 0.03, 0.09):
        assert float(lin.volume(x)) == pytest.approx(2.4e-5 + 4e-4 * x, rel=1e-14)  # eq. 14
        e = x / 0.4
        assert float(cub.volume(x)) == pytest.approx(a * e**3 + b * e**2 + c * e + d, rel=1e-13)  # paper 001 eq. 4
    muscle = pamjax.Muscle(presets.mas10_muscle().force_law, cub, -0.02, 0.1)
    h = 1e-7
    assert float(muscle.volume_slope(0.05)) == pytest.approx(
        float(cub.volume(0.05 + h) - cub.volume(0.05 - h)) / (2 * h), rel=1e-6
    )


def test_slack_and_stiffness():
    muscle = presets.mas10_muscle()
    # A muscle cannot push: at atmospheric pressure and full contraction eq. 7 is negative, the force ≈ 0 (≤ w ln 2).
    assert float(muscle.static_force(0.07, P_ATM, AIR)) < -50
    f = float(muscle.force(0.07, P_ATM, AIR))
    assert 0 <= f < 1e-20
    assert float(muscle.force(0.0, P_ATM + 6e5, AIR)) == pytest.approx(630.0, rel=1e-13)  # slack invisible at 630 N
    h = 1e-7
    fd = (muscle.force(0.03 + h, 4e5, AIR) - muscle.force(0.03 - h, 4e5, AIR)) / (2 * h)
    assert float(muscle.stiffness(0.03, 4e5, AIR)) == pytest.approx(float(fd), rel=1e-6)


def test_end_stops_inactive_inside_and_restoring_outside():
    stops = pamjax.EndStops()
    assert abs(float(stops.force(0.03, 0.0, -0.02, 0.075))) < 1e-30
    assert float(stops.force(0.076, 0.0, -0.02, 0.075)) < -900  # pushes back down beyond x_max (1 mm · 1e6 N/m)
    assert float(stops.force(-0.021, 0.0, -0.02, 0.075)) > 900
    assert float(stops.force(0.076, 0.1, -0.02, 0.075)) < float(stops.force(0.076, 0.0, -0.02, 0.075))  # damping


def test_an_end_stop_width_in_mm_is_refused():
    # `EndStops(width=0.1)` (0.1 mm typed as m) put 21 kN on the payload mid-stroke, silently; a few mm is the most
    # a stop's contact is smoothed over
    with pytest.raises(pamjax.PamjaxInputError, match=r"EndStops\.width = 0\.1 m: more than 0\.005 m.*looks like mm"):
        pamjax.EndStops(width=0.1)
    assert float(pamjax.EndStops(width=2e-3).width) == 2e-3  # a soft stop of a few mm stays legal


@pytest.mark.parametrize("build, match", [
    # the MAS-10's v0 (2.36e-5 m³) typed in litres passed the 0.1 m³ cut-off
    (lambda: pamjax.LinearVolume(0.02356, presets.MAS10_V1),
     r"LinearVolume\.v0 = 0\.02356 m³.*looks like cm³ or litres"),
    # the DMSP-40's cubic volume in litres: 0.5 m³ over 0.4 m is a bore 1.26 m across
    (lambda: pamjax.CubicVolume(jnp.asarray(presets.DMSP40_VOLUME_CUBIC) * 1e3, 0.4),
     r"CubicVolume\.coefficients\[0\].*needs a bore.*looks like litres or cm³"),
    # declared positive (fitted in log space) but only checked finite: a shrinking volume was accepted
    (lambda: pamjax.LinearVolume(2.3e-5, -1e-4), r"LinearVolume\.v1 must be > 0 and finite, got -0\.0001"),
])
def test_volumes_in_litres_and_a_negative_volume_slope_are_refused(build, match):
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        build()


@pytest.mark.parametrize("build, name", [
    (lambda: pamjax.CubicVolume(jnp.asarray(presets.DMSP40_VOLUME_CUBIC), 400.0), "CubicVolume"),
    (lambda: pamjax.TonduLopezForce(radius=5e-3, braid_angle=0.4, nominal_length=300.0), "TonduLopezForce"),
    (lambda: pamjax.ChouHannafordForce(strand_length=0.35, turns=3.0, nominal_length=300.0), "ChouHannafordForce"),
    (lambda: pamjax.BraidVolume(390.0, 7.9, 300.0), "BraidVolume"),
])
def test_a_nominal_length_in_mm_is_refused(build, name):
    # L0 = 400 (mm) simulated silently: no muscle is 10 m long
    match = rf"{name}\.nominal_length = \d+ m: more than 10 m.*looks like mm"
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        build()


@pytest.mark.parametrize("build, name", [
    (lambda: pamjax.ChouHannafordForce(strand_length=390.0, turns=7.9, nominal_length=0.3), "ChouHannafordForce"),
    (lambda: pamjax.BraidVolume(390.0, 7.9, 0.3), "BraidVolume"),
])
def test_a_strand_length_in_mm_is_refused(build, name):
    # b_s = 390 (mm) beside L0 = 0.3 m passed b_s > L0 and simulated a braid 1,000 times too long, silently
    with pytest.raises(pamjax.PamjaxInputError, match=rf"{name}\.strand_length = 390 m: .*looks like mm"):
        build()
    assert float(pamjax.BraidVolume(0.39, 7.9, 0.3).strand_length) == 0.39  # the MAS-10's braid in metres stays legal


@pytest.mark.parametrize("build, name", [
    (lambda: pamjax.TankSystem(presets.mas10_averaged_valve(), 5.0), "TankSystem"),
    (lambda: pamjax.TankFromModel(5.0)(presets.mas10_system(valve="averaged")), "TankSystem"),
    (lambda: pamjax.RegulatorSystem(pamjax.FeedbackRegulator(), 40.0), "RegulatorSystem"),
])
def test_a_tank_volume_in_litres_is_refused(build, name):
    # a 5 l tank typed as 5 (m³) charged 100,000 times too slowly, silently
    with pytest.raises(pamjax.PamjaxInputError, match=rf"{name}\.volume = \d+ m³: more than 0\.1 m³.*litres"):
        build()


def _mas10_law(**kw):
    law = presets.mas10_muscle().force_law
    k0, k1, k2, p_max = (kw.get(k, getattr(law, k)) for k in ("k0", "k1", "k2", "max_pressure"))
    return pamjax.PolynomialForce(law.max_force_coefficients, k0, k1, k2, p_max)


@pytest.mark.parametrize("build, match", [
    # p_max = 6 (bar) gave 602 N instead of 120 N at x = 0.02 m, 3 bar gauge; a config refused it (check_setting)
    (lambda: _mas10_law(max_pressure=6.0), r"PolynomialForce: max_pressure = 6 Pa: that looks like bar"),
    # k2 = 1 (bar) for 1e5 Pa: eq. 7's slope k0/k2 = 103 m², a muscle of 60 MN at 6 bar
    (lambda: _mas10_law(k2=1.0),
     r"PolynomialForce\.k2 = 1 Pa gives eq\. 7 a slope k0/k2 = 102\.8.* looks like k2 in bar"),
    (lambda: _mas10_law(k2=100.0), r"PolynomialForce\.k2 = 100 Pa .*more than 0\.1 m²"),  # kPa
    # b_s < L0: cos θ = 1.5 has no braid angle; eq. 5 returned 88 N (BraidVolume refused the same braid)
    (lambda: pamjax.ChouHannafordForce(0.2, 7.9, 0.3),
     r"ChouHannafordForce\.strand_length \(0\.2\) must exceed nominal_length \(0\.3\)"),
    # r0 = 5 (mm): 2.4e8 N at 3 bar gauge instead of 240 N
    (lambda: pamjax.TonduLopezForce(5.0, 0.4, 0.3), r"TonduLopezForce\.radius = 5 m: more than 0\.1 m.*looks like mm"),
])
def test_force_laws_in_other_units_or_without_a_braid_angle_are_refused(build, match):
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        build()


def test_force_law_unit_checks_leave_legal_and_traced_values_alone():
    # another convention for the unidentifiable k2 (1 Pa, not 1e5): the same law
    law = _mas10_law(k2=1.0, k0=presets.MAS10_K0 * 1e-5, k1=presets.MAS10_K1 * 1e-5)
    assert float(law.static_force(0.02, 3e5)) == pytest.approx(float(_mas10_law().static_force(0.02, 3e5)), rel=1e-12)
    assert float(pamjax.TonduLopezForce(0.02, 0.4, 0.4).radius) == 0.02  # the DMSP-40's 20 mm
    # traced (a fit's trial values, a sweep): not checked
    assert np.isfinite(jax.jit(lambda p: _mas10_law(max_pressure=p, k2=p).static_force(0.0, 3e5))(6.0))


@pytest.mark.parametrize("field", ["force_law", "volume_law"])
def test_a_muscle_without_a_force_or_volume_law_is_refused_by_name(field):
    # Muscle(force_law=None) ended as an AttributeError inside simulate
    laws = dict(force_law=presets.mas10_muscle().force_law, volume_law=pamjax.LinearVolume(2e-5, 1e-4))
    laws[field] = None
    with pytest.raises(pamjax.PamjaxInputError, match=rf"Muscle\.{field} must be an Abstract\w+ .*got NoneType"):
        pamjax.Muscle(**laws, min_position=-0.02, max_position=0.075)
