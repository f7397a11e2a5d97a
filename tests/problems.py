"""Small fit problems built from pamjax's presets, shared by tests that need a quick, well-posed fit (unlike
`helpers.py`, this imports pamjax). The same map is built in tests/test_fit.py and
tests/reliability/test_fit_determinism.py."""

import jax.numpy as jnp
import numpy as np

import pamjax

FORCE_MAP_FREE = ["force_law.max_force_coefficients", "force_law.k0", "force_law.k1"]


def force_map(seed=0, noise=2.0):
    """Paper 000's static force map of the MAS-10 preset: 9 lengths x 7 pressures, `noise` [N] Gaussian noise
    (seeded), slack points at 0 N. Returns (the preset muscle, a `ForceMapExperiment`); 7 free parameters in
    `FORCE_MAP_FREE` (F_max at five nodes, k0, k1), each fit < 15 iterations."""
    muscle = pamjax.presets.mas10_muscle()
    x, p = np.meshgrid(np.linspace(-0.01, 0.07, 9), 101325.0 + np.linspace(0.5e5, 6e5, 7), indexing="ij")
    x, p = x.ravel(), p.ravel()
    f = np.asarray(muscle.static_force(jnp.asarray(x), jnp.asarray(p), pamjax.Air()))
    f = f + noise * np.random.default_rng(seed).standard_normal(f.shape)
    return muscle, pamjax.bench.ForceMapExperiment(x, p, np.maximum(f, 0.0), scale=noise)


def fit_fields(result):
    """Every stored field of a `FitResult` except wall times, for exact (bitwise for floats) comparison."""
    d = result.to_dict()
    del d["fit_s"], d["compile_s"]
    return d
