"""The types of pamjax's public signatures: jaxtyping aliases, as diffrax's `_custom_types.py` has them.

A `…Like` type is what a function or a constructor accepts: a Python number, a NumPy or JAX array, or a tracer under
`jit`/`vmap`/`grad`; an array argument also takes a (nested) list or tuple of numbers, as `jnp.asarray` does. The
others are what pamjax stores and returns: JAX arrays. Shapes are jaxtyping's: `""` a scalar, `" _"` a vector of any
length, `"..."` any shape; a named dimension (`" times"`) must agree between the arguments of one call.

Nothing is checked at run time: the annotations are checked in the test suite (`tests/test_types.py`, beartype
through jaxtyping's import hook). Values are still checked by pamjax itself (`PamjaxInputError`, `_core/errors.py`);
an annotation says what type an argument is, never which values are valid.

The aliases are built once here: a jaxtyping annotation costs 15-100 µs to build, and pamjax's import should not pay
that for each of its signatures.
"""

from collections.abc import Sequence
from typing import Any

from jaxtyping import Array, ArrayLike, Bool, Float, Int, PyTree, Real

# --- accepted -----------------------------------------------------------------------------------------------------
RealScalarLike = Real[ArrayLike, ""]  # a number: bool, int, float, a NumPy scalar, a 0-d array or tracer
IntScalarLike = Int[ArrayLike, ""]
BoolScalarLike = Bool[ArrayLike, ""]
RealSequence = Sequence[RealScalarLike] | Sequence[Sequence[RealScalarLike]]  # [1.0, 2.0], ((0, 1), (2, 3))
RealVectorLike = Real[ArrayLike, " _"] | Sequence[RealScalarLike]  # a vector of any length, a list or tuple
RealArrayLike = Real[ArrayLike, "..."] | RealSequence  # numbers of any shape
TimesLike = Real[ArrayLike, " times"] | Sequence[RealScalarLike]  # the output times of a run [s], increasing
# a column of a component's table (a calibration, tabulated conductances, a sampled signal): one number per entry,
# as many entries in every column of one component
TableLike = Real[ArrayLike, " entries"] | Sequence[RealScalarLike]
BoolTableLike = Bool[ArrayLike, " entries"] | Sequence[bool]  # a column of flags (e.g. where a sweep starts)
# a state variable (a pressure, a position): a number per run, or with the leading axes of a trajectory or a batch,
# the same for every variable of one state
StateLike = Real[ArrayLike, "*batch"]

# --- stored and returned -------------------------------------------------------------------------------------------
RealScalar = Real[Array, ""]  # a component's scalar parameter after its converter (an int becomes a float)
RealVector = Real[Array, " _"]
RealArray = Real[Array, "..."]
Table = Real[Array, " entries"]
FloatScalar = Float[Array, ""]
FloatVector = Float[Array, " _"]
FloatArray = Float[Array, "..."]
BoolArray = Bool[Array, "..."]
IntArray = Int[Array, "..."]
Series = Float[Array, " times"]  # one value per output time
Result = Int[Array, "..."]  # equinox/diffrax result codes, one per run or lane

PyTreeLike = PyTree[Any]  # a pytree whose leaves pamjax does not constrain (a model, a state, solver options)

__all__ = [
    "Array", "ArrayLike", "Bool", "BoolArray", "BoolScalarLike", "BoolTableLike", "Float", "FloatArray", "FloatScalar",
    "FloatVector", "Int", "IntArray", "IntScalarLike", "PyTree", "PyTreeLike", "Real", "RealArray", "RealArrayLike",
    "RealScalar", "RealScalarLike", "RealSequence", "RealVector", "RealVectorLike", "Result", "Series", "StateLike",
    "Table", "TableLike", "TimesLike",
]
