"""The shared random generator (xoshiro128**; spec in docs/DESIGN.md), from the C++ core."""
from cdam_core._core import Rng

__all__ = ["Rng"]
