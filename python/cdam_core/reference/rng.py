"""The shared random generator (xoshiro128**), pure-Python twin of C++ ``cdam::Rng``.

Specified in docs/DESIGN.md: 32-bit state s0..s3 seeded splitmix-style from a uint32 seed;
next() is xoshiro128** (Blackman and Vigna); uniform() = (next() >> 8) * 2^-24 in [0, 1);
index(n) = (next() * n) >> 32; normal() = sqrt(-2 ln(1 - u1)) cos(2 pi u2), two draws.
All arithmetic is on Python ints masked to 32 bits.
"""
from __future__ import annotations

import math

import numpy as np

from cdam_core.reference._checks import integer, real

_MASK = 0xFFFFFFFF


def _rotl(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _MASK


class Rng:
    """xoshiro128** generator seeded from a uint32 ``seed`` (0 .. 2^32 - 1)."""

    def __init__(self, seed: int = 0):
        x = integer(seed, "seed", minimum=0, maximum=_MASK)
        s = []
        for _ in range(4):
            x = (x + 0x9E3779B9) & _MASK
            z = x
            z = ((z ^ (z >> 16)) * 0x85EBCA6B) & _MASK
            z = ((z ^ (z >> 13)) * 0xC2B2AE35) & _MASK
            z ^= z >> 16
            s.append(z)
        self._s = s

    @classmethod
    def from_state(cls, s0: int, s1: int, s2: int, s3: int) -> "Rng":
        """Generator with the raw state (s0, s1, s2, s3); not all zero."""
        state = [integer(v, f"s{k}", minimum=0, maximum=_MASK)
                 for k, v in enumerate((s0, s1, s2, s3))]
        if not any(state):
            raise ValueError("s0: the state must not be all zero")
        rng = cls.__new__(cls)
        rng._s = state
        return rng

    @property
    def state(self) -> tuple[int, int, int, int]:
        """The current state words (s0, s1, s2, s3)."""
        return tuple(self._s)

    def next_u32(self) -> int:
        """Next raw 32-bit output."""
        s = self._s
        result = (_rotl((s[1] * 5) & _MASK, 7) * 9) & _MASK
        t = (s[1] << 9) & _MASK
        s[2] ^= s[0]
        s[3] ^= s[1]
        s[1] ^= s[2]
        s[0] ^= s[3]
        s[2] ^= t
        s[3] = _rotl(s[3], 11)
        return result

    def uniform(self, a: float = 0.0, b: float = 1.0) -> float:
        """a + (b - a) * u with u = (next >> 8) * 2^-24 in [0, 1); one draw."""
        a = real(a, "a")
        b = real(b, "b")
        return a + (b - a) * ((self.next_u32() >> 8) * 2.0 ** -24)

    def index(self, n: int) -> int:
        """Integer in 0 .. n-1 as (next * n) >> 32; one draw; 1 <= n <= 2^32 - 1."""
        n = integer(n, "n", minimum=1, maximum=_MASK)
        return (self.next_u32() * n) >> 32

    def normal(self) -> float:
        """Standard normal by Box-Muller, sqrt(-2 ln(1 - u1)) cos(2 pi u2); two draws."""
        u1 = self.uniform()
        u2 = self.uniform()
        return math.sqrt(-2.0 * math.log(1.0 - u1)) * math.cos(2.0 * math.pi * u2)

    def uniform_array(self, n: int, a: float = 0.0, b: float = 1.0) -> np.ndarray:
        """n uniform draws in order, as a float64 array."""
        n = integer(n, "n", minimum=0)
        a = real(a, "a")
        b = real(b, "b")
        return np.array([a + (b - a) * ((self.next_u32() >> 8) * 2.0 ** -24)
                         for _ in range(n)], dtype=np.float64)
