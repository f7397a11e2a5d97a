"""Re-derive the MAS-10-300 / DMSP-40-400 preset numbers documented in `pamjax/presets.py` and compare.

    python fits/derive_presets.py [--out results/derive_presets] [--overwrite]

Steps (presets.py docstring items 1-3): per-length affine fit F = c0 + c1 p of the DMSP-20-300 force map (non-zero
points), the force at p_max = 0.6 MPa gauge and slope ∂F/∂p; a least-squares quartic in ε through those five 6-bar
forces plus F = 0 at ε = 0.25, scaled to the datasheet force at ε = 0 (630 N MAS-10, 6000 N DMSP-40) and converted
to x = ε L0; k0, k1 from a line through the slopes (same scale, k2 = 1e5 Pa). Volume by virtual work,
V(x) − v0 = ∫₀ˣ F_max/p_max dx (cumulative trapezoid, 201 points over the stroke), v1 its least-squares slope
(MAS-10) or a cubic in ε with d fixed to the cylinder (DMSP-40: the fitted constant term is discarded). m1…m9 by
`pamjax.fit_averaged_valve` on the exact-edge valve (41 × 41 grid).
"""

import argparse
import pathlib

import numpy as np

from pamjax.gallery import json_text, refuse_existing  # noqa: E402
from pamjax.gallery.procedures.force_map import (  # noqa: E402  (the derivation's steps)
    P,
    scaled_muscle,
    virtual_work_volume,
)


def derive(with_valve=True):
    out = {}
    a, k0, k1 = scaled_muscle(630.0, 0.3)  # MAS-10-300 datasheet: 630 N at 6 bar, 300 mm
    eps, dv = virtual_work_volume(a * 0.3 ** np.arange(5), 0.3)
    out["mas10"] = dict(a=a.tolist(), k0=k0, k1=k1, v0=np.pi / 4 * 0.01**2 * 0.3, v1=np.polyfit(eps * 0.3, dv, 1)[0])
    a40, k0_40, k1_40 = scaled_muscle(6000.0, 0.4)  # DMSP-40-400: 6000 N, 400 mm (paper 001)
    eps, dv = virtual_work_volume(a40 * 0.4 ** np.arange(5), 0.4)
    cubic = P.polyfit(eps, dv, 3)
    out["dmsp40"] = dict(a=a40.tolist(), k0=k0_40, k1=k1_40,
                         volume_cubic=[np.pi / 4 * 0.04**2 * 0.4, *cubic[1:].tolist()])
    if with_valve:
        import jax

        jax.config.update("jax_enable_x64", True)
        import pamjax

        fitted, report = pamjax.fit_averaged_valve(pamjax.presets.mas10_valve("exact"), pamjax.Air())
        out["mas10_averaged_valve"] = np.asarray(fitted.coefficients).tolist()
        out["averaged_valve_fit"] = report
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/derive_presets")
    parser.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    args = parser.parse_args()
    refuse_existing("derive_presets.py", [pathlib.Path(args.out) / "derived_presets.json"], args.overwrite)
    from pamjax import presets

    derived = derive()
    folder = pathlib.Path(args.out)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "derived_presets.json").write_text(json_text(derived, indent=2))
    m, d = derived["mas10"], derived["dmsp40"]
    rows = [
        ("MAS-10-300", "a0..a4", m["a"], presets.MAS10_MAX_FORCE_COEFFICIENTS),
        ("MAS-10-300", "k0", m["k0"], presets.MAS10_K0),
        ("MAS-10-300", "k1", m["k1"], presets.MAS10_K1),
        ("MAS-10-300", "v0", m["v0"], presets.MAS10_V0),
        ("MAS-10-300", "v1", m["v1"], presets.MAS10_V1),
        ("MAS-10-300", "m1..m9", derived["mas10_averaged_valve"], presets.MAS10_AVERAGED_VALVE),
        ("DMSP-40-400", "a0..a4", d["a"], presets.DMSP40_MAX_FORCE_COEFFICIENTS),
        ("DMSP-40-400", "k0", d["k0"], presets.DMSP40_K0),
        ("DMSP-40-400", "k1", d["k1"], presets.DMSP40_K1),
        ("DMSP-40-400", "d,c,b,a", d["volume_cubic"], presets.DMSP40_VOLUME_CUBIC),  # volume cubic, ascending in ε
    ]
    for muscle, name, got, preset in rows:
        rel = np.max(np.abs(np.subtract(got, preset)) / np.maximum(np.abs(preset), 1e-300))
        print(f"{muscle:11s} {name:8s} max relative difference to presets.py: {rel:.1e}")
    print("averaged valve fit:", derived["averaged_valve_fit"])
    print(f"wrote {folder / 'derived_presets.json'}")


if __name__ == "__main__":
    main()
