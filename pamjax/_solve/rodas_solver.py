"""`Rodas5`: the RODAS5 step of `pamjax/_solve/rodas.py` (the scheme, its source and its checks are described there) as
a diffrax solver. A module of its own: importing diffrax costs ~0.4 s, which a workflow that never solves adaptively
(a fit on the fixed grids, loaded from the cache) does not pay."""

from typing import ClassVar

import diffrax as dfx
from jax.flatten_util import ravel_pytree

from .rodas import rodas5_step


class Rodas5(dfx.AbstractAdaptiveSolver):
    """L-stable, stiffly accurate Rosenbrock method of order 5 with an embedded order-4 error estimate (RODAS5).

    For stiff plants (a sticking payload under the smooth Coulomb sign): steps are bounded by the tolerance, where
    Tsit5 is held at its stability limit. Per step: one forward-mode Jacobian (with ∂f/∂t), one small matrix
    inverse and nine right-hand-side evaluations. Not for the switching valve's smoothed edges (Tsit5 is faster
    there). Source: Di Marzo (1993) in Hairer & Wanner, *Solving ODEs II* (1996), Sec. IV.7.
    """

    term_structure: ClassVar = dfx.AbstractTerm
    interpolation_cls: ClassVar = dfx.ThirdOrderHermitePolynomialInterpolation

    def order(self, terms):
        return 5

    def error_order(self, terms):
        return 5  # k_8 = y1 - (embedded order-4 solution): O(h^5)

    def init(self, terms, t0, t1, y0, args):
        return None

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del solver_state, made_jump
        z0, unravel = ravel_pytree(y0)

        def f(t, z):
            return ravel_pytree(terms.vf(t, unravel(z), args))[0]

        h = t1 - t0
        z1, error, f0 = rodas5_step(f, t0, z0, h)
        y1 = unravel(z1)
        dense_info = dict(y0=y0, y1=y1, k0=unravel(h * f0), k1=unravel(h * f(t1, z1)))
        return y1, unravel(error), dense_info, None, dfx.RESULTS.successful
