"""NARX / ARX orders (na, nb, nk): parsing, checking and the facts derived from them.

y(t) depends on y(t-1) .. y(t-na) and u(t-nk) .. u(t-nk-nb+1); the first row that has all of
them is t0 = max(na, nk + nb - 1). One network regressor has na * m + nb * i elements.
"""
from __future__ import annotations

from typing import NamedTuple

__all__ = ["Orders", "parse_orders"]

MAX_LAG = 1_000_000   # a lag beyond a million samples is a typo, not a model (and would overflow)


class Orders(NamedTuple):
    na: int
    nb: int
    nk: int

    @property
    def t0(self) -> int:
        return max(self.na, self.nk + self.nb - 1)

    def n_regressors(self, n_inputs: int, n_outputs: int) -> int:
        return self.na * n_outputs + self.nb * n_inputs


def parse_orders(value, name: str = "narx") -> Orders:
    """Orders from "na,nb,nk", a 3-sequence or an Orders; ValueError naming ``name``."""
    if isinstance(value, str):
        parts = [p.strip() for p in value.split(",")]
    else:
        try:
            parts = list(value)
        except TypeError:
            raise ValueError(f"{name}: expected (na, nb, nk), got {value!r}") from None
    if len(parts) != 3:
        raise ValueError(f"{name}: expected three orders na,nb,nk, got {value!r}")
    out = []
    for label, p in zip(("na", "nb", "nk"), parts):
        if isinstance(p, bool):
            raise ValueError(f"{name}: {label} must be an integer, got {p!r}")
        try:
            v = int(p)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: {label} must be an integer, got {p!r}") from None
        if isinstance(p, float) and v != p:
            raise ValueError(f"{name}: {label} must be an integer, got {p!r}")
        if not 0 <= v <= MAX_LAG:
            raise ValueError(f"{name}: {label} must be in 0 .. {MAX_LAG}, got {v}")
        out.append(v)
    if out[0] + out[1] < 1:
        raise ValueError(f"{name}: na + nb must be >= 1, got {value!r}")
    return Orders(*out)
