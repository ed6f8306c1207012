"""Units per column: the standard columns' units, how a declared unit is compared with them, and
the check a physical model makes on the units of the signals it is given.

A record's units are the sidecar's ``units`` (column -> text) over the standard units
(``STANDARD_UNITS``). Two spellings of one unit are the same unit: ``"N m"``, ``"N*m"``,
``"N.m"``, ``"N·m"`` and ``"Nm"``; ``"rad/s"`` and ``"rad s^-1"`` are not recognised as one
(written the way this package writes them, the comparison holds).

Where a standard column's physical meaning is fixed (``t`` in s; the angles ``phi, theta, psi,
q1, q2, theta_m1, theta_m2`` in rad; the positions ``X, Y, Z`` in m), a declared unit must be
the standard one (``deg`` for an angle is an error: convert with a column map, e.g.
``--map phi=phi*0.017453292519943295``, which leaves the converted column in the standard unit).
The inputs ``T`` (N) and ``tau_*`` (N m) may also be *commands* in normalised units, as flight
controllers log them (PX4's thrust 0..1 of full thrust): a unit text starting with
``normalised`` / ``normalized`` / ``dimensionless`` declares that. Any other unit on them (kN,
N cm, g) is an error. A physical model (the grey-box models) then checks the units of the
signals it uses (:func:`check_model_units`): it refuses a normalised command, and a unit other
than the one its equations are written in.
"""
from __future__ import annotations

import re

__all__ = ["STANDARD_UNITS", "FIXED_UNITS", "COMMAND_COLUMNS", "same_unit", "is_normalised",
           "check_standard_units", "check_model_units"]

STANDARD_UNITS = {
    "t": "s",
    "T": "N",
    "tau_phi": "N m",
    "tau_theta": "N m",
    "tau_psi": "N m",
    "tau_m1": "N m",
    "tau_m2": "N m",
    "phi": "rad",
    "theta": "rad",
    "psi": "rad",
    "X": "m",
    "Y": "m",
    "Z": "m",
    "q1": "rad",
    "q2": "rad",
    "theta_m1": "rad",
    "theta_m2": "rad",
}
# inputs that a flight controller may log as normalised commands instead of N / N m
COMMAND_COLUMNS = ("T", "tau_phi", "tau_theta", "tau_psi", "tau_m1", "tau_m2")
FIXED_UNITS = {c: u for c, u in STANDARD_UNITS.items() if c not in COMMAND_COLUMNS}

_NORMALISED = ("normalised", "normalized", "dimensionless")


def _canonical(unit: str) -> str:
    u = unit.strip().replace("·", " ").replace("*", " ")
    u = re.sub(r"(?<=[A-Za-z])\.(?=[A-Za-z])", " ", u)     # N.m
    u = re.sub(r"\s+", " ", u)
    return "N m" if u == "Nm" else u


def same_unit(a: str, b: str) -> bool:
    """True when ``a`` and ``b`` are one unit in two spellings (module doc)."""
    return _canonical(a) == _canonical(b)


def is_normalised(unit: str) -> bool:
    """True for a unit text declaring a normalised (dimensionless) command."""
    return unit.strip().lower().startswith(_NORMALISED)


def check_standard_units(units: dict, columns, where: str) -> None:
    """The declared ``units`` (column -> text) of the standard ``columns`` against the standard
    units (module doc); ValueError naming the column, its unit and the standard one."""
    for col in ["t", *columns]:
        unit = units.get(col)
        if unit is None or col not in STANDARD_UNITS or same_unit(unit, STANDARD_UNITS[col]):
            continue
        std = STANDARD_UNITS[col]
        if col in COMMAND_COLUMNS:
            if is_normalised(unit):
                continue
            raise ValueError(f"{where}: sidecar field 'units': {col}: {unit!r} is neither the "
                             f"standard {std!r} nor a normalised command (a unit starting "
                             f"with 'normalised'); convert the column (a column map with a "
                             f"factor) or rename it")
        raise ValueError(f"{where}: sidecar field 'units': {col}: declared {unit!r}, but the "
                         f"standard column {col} is in {std!r}; convert it (a column map with "
                         f"a factor, e.g. {col}={col}*FACTOR) or rename the column")


def check_model_units(model: str, needs: dict, given: dict, where: str) -> None:
    """A physical model's check of its signals' units: ``needs`` {signal: unit its equations
    use, or None where either of several is fine}, ``given`` {signal: (column, declared unit or
    None)}. A normalised command is refused for every signal (a physical model's parameters
    would come out in command units); a declared unit other than the one needed is refused.
    ValueError naming the signal, its column and both units."""
    for sig, (col, unit) in given.items():
        if unit is None:
            continue
        if is_normalised(unit):
            raise ValueError(f"{where}: {sig} (column {col}) is a normalised command "
                             f"({unit!r}); the {model} model needs it in physical units"
                             + (f" ({needs[sig]})" if needs.get(sig) else ""))
        need = needs.get(sig)
        if need is not None and not same_unit(unit, need):
            raise ValueError(f"{where}: {sig} (column {col}) is in {unit!r}; the {model} "
                             f"model needs {need!r}")
