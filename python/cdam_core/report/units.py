"""Units of the grey-box parameters, for the reports' tables.

A parameter's unit follows from its model equation: ``F`` is the unit of the equation's
force or torque signal and ``X`` that of its coordinate (``rigid_axis``: EMPS's N and m, or
N m and rad for a rotary axis; ``flexible_joint``: N m and rad). The flight models are in the
dataset format's SI units (docs PAPER.md: thrust N, torques N m, angles rad, positions m).
A parameter not listed here has its unit left blank in the table rather than guessed.
"""
from __future__ import annotations

__all__ = ["parameter_unit", "channel_unit", "derived_unit"]

_SIMPLER = {"N s²/m": "kg", "N m s²/rad": "kg m²"}

# model parameter -> unit template in F (force/torque) and X (coordinate)
_DECLARED = {
    "rigid_axis": {"M": "F s²/X", "Fv": "F s/X", "offset": "F", "G": "F", "Gc": "F"},
    "flexible_joint": {"Im": "F s²/X", "Dm": "F s/X", "Ks": "F/X", "Kd": "F s/X",
                       "I": "F s²/X", "Dl": "F s/X", "G": "F", "Gc": "F", "offset_m": "F",
                       "offset_l": "F"},
}
_FLIGHT = {"m": "kg", "Kx": "N s/m", "Ky": "N s/m", "Kz": "N s/m", "Jx": "kg m²",
           "Jy": "kg m²", "Jz": "kg m²", "Kphi": "N m s/rad", "Ktheta": "N m s/rad",
           "Kpsi": "N m s/rad",
           **{f"{p}{i}": u for i in (1, 2) for p, u in (("Im", "kg m²"), ("Dm", "N m s/rad"),
                                                        ("Ks", "N m/rad"), ("Kd", "N m s/rad"),
                                                        ("Dl", "N m s/rad"), ("g", "N m"))},
           "p1": "kg m²", "p2": "kg m²", "p3": "kg m²"}
# effect parameter (the part after "effect@channel.") -> template
_EFFECT = {"Fc": "F", "dFc": "F", "dFv": "F s/X", "Fc_pos": "F", "Fc_neg": "F",
           "Fv_pos": "F s/X", "Fv_neg": "F s/X", "width": "X", "K3": "F/X³", "delay": "s",
           "mass": "kg", "m": "kg"}
# derived quantity (the declared model's ``derived``) -> template, on the model's first channel
_DERIVED = {"rigid_axis": {"gravity_amplitude": "F", "gravity_zero_rad": "X"},
            "flexible_joint": {"gravity_amplitude": "F", "gravity_zero_rad": "X",
                               "encoder_zero_offset_rad": "X", "torque_offset": "F"}}
# the (force, coordinate) signal pair of each equation channel
_PAIRS = {"rigid_axis": {"tau": ("tau", "q")},
          "flexible_joint": {"tau_m": ("tau_m", "theta_m"), "tau_l": ("tau_m", "q")}}


def _fill(template: str, force: str | None, coord: str | None) -> str:
    if force is None or coord is None:
        return ""
    u = template.replace("F", force).replace("X", coord)
    return _SIMPLER.get(u, u)


def parameter_unit(model: str, name: str, units: dict | None = None) -> str:
    """The unit of parameter ``name`` (``"M"``, ``"coulomb_friction@tau.Fc"``) of ``model``,
    given the record's signal units (``{"tau": "N", "q": "m"}``); "" when unknown."""
    units = units or {}
    if model in ("quadrotor", "aerial_manipulator"):
        if "@" not in name:
            return _FLIGHT.get(name, "")
        eff, _, par = name.partition(".")
        return {"delay": "s", "mass": "kg", "m": "kg"}.get(par, "")
    pairs = _PAIRS.get(model, {})
    if "@" not in name:
        template = _DECLARED.get(model, {}).get(name)
        channel = next(iter(pairs), None)
        if model == "flexible_joint" and name in ("I", "Dl", "G", "Gc", "offset_l"):
            channel = "tau_l"
    else:
        head, _, par = name.partition(".")
        channel = head.split("@", 1)[1] if "@" in head else None
        template = _EFFECT.get(par)
    if template is None:
        return ""
    if "F" not in template and "X" not in template:
        return template
    force, coord = pairs.get(channel, (None, None))
    return _fill(template, units.get(force), units.get(coord))


def channel_unit(model: str, channel: str, units: dict | None = None) -> str:
    """The unit of an equation channel's residual (its force or torque signal's unit), or of an
    output channel (its own unit); "" when unknown."""
    if model not in _PAIRS:    # flight models: equation and output channels share names
        return ""
    units = units or {}
    pair = _PAIRS[model].get(channel)
    return units.get(pair[0] if pair else channel, "")


def derived_unit(model: str, name: str, units: dict | None = None) -> str:
    """The unit of a derived quantity (``"gravity_zero_rad"``) of ``model``; "" when unknown."""
    template = _DERIVED.get(model, {}).get(name)
    if template is None:
        return ""
    force, coord = next(iter(_PAIRS.get(model, {}).values()), (None, None))
    return _fill(template, (units or {}).get(force), (units or {}).get(coord))
