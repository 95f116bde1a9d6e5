"""Whole-width vector registers for one compiled kernel: ``wide_vectors()`` as the first
statement of an ``@numba.njit`` function lets LLVM vectorise its loops with the widest
registers the processor has (512 bits where it has AVX-512), where by default it keeps to 256.

LLVM prefers 256-bit vectors on Intel processors with AVX-512 (the first ones slowed their clock
down for 512-bit instructions; recent ones do not). Numba can change that only for a whole
process (``NUMBA_CPU_FEATURES=...,-prefer-256-bit``), which would change every kernel of the
caller's program too. This intrinsic changes it for the function that calls it, through LLVM's
per-function attributes ``"prefer-vector-width"="512"`` (the loop vectoriser's width) and
``"min-legal-vector-width"="512"`` (keeps the wide vectors legal after the function is inlined
into a caller without the attribute). On a processor without AVX-512 both are no-ops: the
vector width is what the processor has.

Use it only in a kernel whose arithmetic does not depend on the vector width: one compiled
without ``reassoc`` (no sum reordered across lanes), where a wider vector computes the same
elementwise operations on more lanes at once and so returns the same bits
(:mod:`sidql.keyframes.single_costs`; tests/test_wide_vectors.py checks it).
"""

from __future__ import annotations

from numba.core import types
from numba.extending import intrinsic

#: The attributes set on the calling function (LLVM's string attributes).
ATTRIBUTES = ('"prefer-vector-width"="512"', '"min-legal-vector-width"="512"')


@intrinsic
def wide_vectors(typingctx):
    """No-op at run time; at compile time marks the calling kernel for 512-bit vectors."""

    def codegen(context, builder, signature, args):
        attributes = builder.function.attributes
        for a in ATTRIBUTES:  # llvmlite's add() accepts only its list of named attributes;
            set.add(attributes, a)  # a string attribute is written out as it is given
        return context.get_dummy_value()

    return types.none(), codegen
