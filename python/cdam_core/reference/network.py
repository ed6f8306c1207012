"""The BPNetwork estimator on the numpy twin: the same estimator logic as cdam_core.BPNetwork
(scaling, initial weights, NARX design), with every kernel taken from cdam_core.reference."""
from __future__ import annotations

from cdam_core.network import BPNetwork as _CoreBPNetwork


class BPNetwork(_CoreBPNetwork):
    """`cdam_core.BPNetwork` computed by the numpy reference kernels (no C++)."""

    _backend = "reference"

    @staticmethod
    def _kernels():
        from cdam_core import reference
        return reference

    @staticmethod
    def _scaler():
        from cdam_core.reference import MinMaxScaler
        return MinMaxScaler()

    def _train_kwargs(self, callback):
        return {}
