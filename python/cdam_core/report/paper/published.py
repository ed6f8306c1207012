"""The paper's published numbers (Xi, Ding, Ma, J. Sensors 2024, 2136038), typed from
``../shared/docs/PAPER.md``: Table 2 (test on the last 10 s), Table 3 (validation record),
final fitness (adaptation value) and run time per algorithm ("Algorithm 1/2/3" of Remark 5 are
IBOA-BP, BOA-BP, CABC-BP)."""
from __future__ import annotations

__all__ = ["OUTPUTS", "ALGORITHMS", "TABLE2", "TABLE3", "FITNESS", "RUN_TIME_S", "LABEL"]

OUTPUTS = ("theta", "phi", "psi", "X", "Y", "Z", "q1", "q2")   # the paper's row order
ALGORITHMS = ("iboa", "boa", "cabc")
LABEL = {"iboa": "IBOA-BP", "boa": "BOA-BP", "cabc": "CABC-BP", "bp": "BP"}

TABLE2 = {
    "theta": {"iboa": 0.9661, "boa": 0.9288, "cabc": 0.8699},
    "phi": {"iboa": 0.9671, "boa": 0.9199, "cabc": 0.8671},
    "psi": {"iboa": 0.8706, "boa": 0.8023, "cabc": 0.7327},
    "X": {"iboa": 0.9526, "boa": 0.9121, "cabc": 0.8515},
    "Y": {"iboa": 0.9769, "boa": 0.9562, "cabc": 0.9199},
    "Z": {"iboa": 0.9922, "boa": 0.9815, "cabc": 0.9600},
    "q1": {"iboa": 0.9991, "boa": 0.9980, "cabc": 0.9940},
    "q2": {"iboa": 0.9914, "boa": 0.9678, "cabc": 0.9024},
}
TABLE3 = {
    "theta": {"iboa": 0.9157, "boa": 0.8520, "cabc": 0.8946},
    "phi": {"iboa": 0.9685, "boa": 0.8874, "cabc": 0.9239},
    "psi": {"iboa": 0.9755, "boa": 0.8955, "cabc": 0.8497},
    "X": {"iboa": 0.8630, "boa": 0.8252, "cabc": 0.7643},
    "Y": {"iboa": 0.9288, "boa": 0.9210, "cabc": 0.8436},
    "Z": {"iboa": 0.7977, "boa": 0.7993, "cabc": 0.5959},
    "q1": {"iboa": 0.9696, "boa": 0.9359, "cabc": 0.8874},
    "q2": {"iboa": 0.9913, "boa": 0.9785, "cabc": 0.9735},
}
FITNESS = {"iboa": 0.9962, "boa": 0.9844, "cabc": 0.9684}
RUN_TIME_S = {"iboa": 2.4, "boa": 3.7, "cabc": 1.8}
