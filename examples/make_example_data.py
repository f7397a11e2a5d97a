"""Generate the small bundled example recordings used by `examples/fit_example.toml` (committed CSVs, < 200 kB).

pamjax's MAS-10 preset with the averaged valve (eq. 13) and exact stick-slip friction (`KarnoppFriction`: the
payload holds still until the net force exceeds F_c), integrated on a 0.25 ms grid, sampled at 50 Hz with the hybrid
bench's noise levels (2 kPa, 0.1 mm), seeded: triangle duty 0.05–0.95 at 0.25 Hz (8 s) and a 5e-5 m³ tank charged at
duty 0.5 (2 s).

    python examples/make_example_data.py [--overwrite]
"""

import argparse
import pathlib

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax import presets  # noqa: E402

HERE = pathlib.Path(__file__).parent


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--overwrite", action="store_true")
    args = ap.parse_args()
    system = presets.mas10_system(valve="averaged", friction="karnopp")
    run = pj.synthetic_recording(system, pj.Triangle(0.05, 0.95, 0.25), np.arange(0.0, 8.0 + 1e-9, 0.02),
                                 noise=dict(pressure=2e3, position=1e-4), seed=1, name="triangle_025", grid_step=2.5e-4)
    run.to_csv(HERE / "triangle_025.csv", overwrite=args.overwrite)
    tank = pj.TankFromModel(5e-5)(system)
    charge = pj.synthetic_recording(tank, pj.Constant(0.5), np.arange(0.0, 2.0 + 1e-9, 0.02), noise=dict(pressure=2e3),
                                    seed=2, name="tank_charge_050")
    charge.to_csv(HERE / "tank_charge_050.csv", overwrite=args.overwrite)
    print("wrote", HERE / "triangle_025.csv", HERE / "tank_charge_050.csv")


if __name__ == "__main__":
    main()
