"""The model as the firmware runs it, read from a model file: a BP network in its input space
(:class:`FirmwareModel`), or a dynamic kind, arx / hybrid / greybox
(:class:`cdam_core.firmware.step.StepFirmwareModel`)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdam_core import _core
from cdam_core.firmware.numbers import theta_fnv1a
from cdam_core.firmware.step import StepFirmwareModel, step_model
from cdam_core.models.file import read_model_file

__all__ = ["FirmwareModel", "StepFirmwareModel", "load_firmware_model", "theta_fnv1a"]


@dataclass
class FirmwareModel:
    """What the firmware needs of a model file, in the network's input space."""

    inputs: list            # names of the network inputs (regressor elements for NARX)
    outputs: list
    hidden: int
    activation: str         # "tansig" or "logsig"
    theta: np.ndarray       # (D,) float64, [W1(:); b1; W2(:); b2]
    x_min: np.ndarray       # (I,) per network input
    x_max: np.ndarray
    y_min: np.ndarray       # (O,)
    y_max: np.ndarray
    sha256: str             # checksum of the source model file
    narx: tuple | None = None
    source: str = ""

    @property
    def kind(self) -> str:
        """The model file's kind (a network; the dynamic kinds are StepFirmwareModel's)."""
        return "bp_network"

    @property
    def n_inputs(self) -> int:
        return len(self.x_min)

    @property
    def n_outputs(self) -> int:
        return len(self.y_min)

    def scale_inputs(self, X) -> np.ndarray:
        """Min-max to [-1, 1] per network input (a constant column maps to 0)."""
        return _minmax(np.asarray(X, dtype=np.float64), self.x_min, self.x_max)

    def forward_normalised(self, Xn) -> np.ndarray:
        """The Python model's normalised outputs (float64, the core's forward pass)."""
        return _core.mlp_forward(np.asarray(self.theta, np.float64), np.asarray(Xn, np.float64),
                           self.hidden, self.n_outputs, self.activation)

    def predict(self, X) -> np.ndarray:
        """Physical outputs for physical network inputs (float64)."""
        yn = self.forward_normalised(self.scale_inputs(X))
        span = self.y_max - self.y_min
        return np.where(span > 0, (yn + 1) * span / 2 + self.y_min, self.y_min)


def _minmax(X, lo, hi):
    span = hi - lo
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(span > 0, 2 * (X - lo) / np.where(span > 0, span, 1) - 1, 0.0)


def load_firmware_model(path) -> FirmwareModel | StepFirmwareModel:
    """Read a model file into what the firmware runs: a FirmwareModel for ``bp_network``, a
    StepFirmwareModel for ``arx``, ``hybrid``, ``greybox``, ``quad_physics``, ``quad_hybrid`` and a
    ``bp_network`` with a monitor section (run one sample at a time beside its monitor).

    Raises FileNotFoundError for a missing file and ValueError for a corrupt or inconsistent
    one, or for a model (a grey-box model's declared model or effect) the firmware cannot run.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MODEL: no such file: {path}")
    mf = read_model_file(path)
    if mf.kind != "bp_network" or mf.monitor is not None:   # a monitored network: one sample
        try:                                                   # at a time, beside its monitor
            return step_model(mf, str(path))
        except ValueError as exc:
            raise ValueError(f"{exc} ({path})") from None
    net = mf.model
    ins, outs, m = mf.inputs, mf.outputs, net.n_outputs_
    xmin, xmax = net.scaler_x_.data_min_, net.scaler_x_.data_max_
    ymin, ymax = net.scaler_y_.data_min_, net.scaler_y_.data_max_
    names = list(ins)
    if net.narx is not None:
        na, nb, _ = net.narx
        names = [f"{outs[c]}[t-{a}]" for a in range(1, na + 1) for c in range(m)]
        names += [f"{ins[c]}[t-nk-{b}]" for b in range(nb) for c in range(len(ins))]
        xmin = np.concatenate([ymin] * na + [xmin] * nb)
        xmax = np.concatenate([ymax] * na + [xmax] * nb)
    return FirmwareModel(names, list(outs), int(net.hidden_), net.activation,
                         np.asarray(net.theta_, np.float64), xmin, xmax, ymin, ymax,
                         mf.sha256, net.narx, str(path))
