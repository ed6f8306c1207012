"""Effects that can hide in simulated data: registry with documentation, parameters, defaults.

Each effect is present in the physics when switched on; the flight's sidecar lists it under
``effects`` (with its parameters) but declares it in ``model`` only when asked (``--declare``).
``arm_coupling`` is always physically present (the simulator is fully coupled); the paper's
simplified model (8) lacks it, so it is listed as present and undeclared unless declared.

Use :func:`parse_effect` for the command-line form ``NAME[:param=value,...]`` and
:func:`resolve_effects` to turn a list into plant/controller overrides.
"""
from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["EffectSpec", "EFFECTS", "parse_effect", "resolve_effects", "describe_effects"]


@dataclass(frozen=True)
class EffectSpec:
    """One effect: what it is, where it shows, its parameters ``{name: (default, unit, doc)}``."""

    name: str
    doc: str
    channels: tuple
    params: dict = field(default_factory=dict)


EFFECTS = {e.name: e for e in (
    EffectSpec("coulomb_friction",
               "Dry friction at each motor after the gearbox, Fc tanh(theta_m'/eps), in eq. (3).",
               ("tau_m1", "tau_m2", "theta_m1", "theta_m2"),
               {"Fc1": (0.03, "N m", "joint 1 friction level"),
                "Fc2": (0.02, "N m", "joint 2 friction level"),
                "eps": (0.05, "rad/s", "velocity of the tanh smoothing")}),
    EffectSpec("backlash",
               "Dead band in each cable: the spring acts on dead_zone(theta_m - q, width) "
               "(total width; the Kd term is unchanged).",
               ("q1", "q2", "theta_m1", "theta_m2"),
               {"width1": (0.02, "rad", "cable 1 dead-band total width"),
                "width2": (0.02, "rad", "cable 2 dead-band total width")}),
    EffectSpec("hardening_stiffness",
               "Cubic cable spring: tau_l += K3 dz^3 (dz the cable deflection).",
               ("q1", "q2", "theta_m1", "theta_m2"),
               {"K3_1": (5000.0, "N m/rad^3", "cable 1 cubic coefficient"),
                "K3_2": (5000.0, "N m/rad^3", "cable 2 cubic coefficient")}),
    EffectSpec("actuator_delay",
               "Commands applied late (rounded to whole 1 kHz ticks): joint torque commands "
               "(C610 bus latency) and/or rotor commands (ESC latency). The logged inputs are "
               "the commands as sent.",
               ("tau_m1", "tau_m2", "T", "tau_phi", "tau_theta", "tau_psi"),
               {"joint": (0.010, "s", "joint command delay"),
                "rotor": (0.0, "s", "rotor command delay")}),
    EffectSpec("payload_mass",
               "Extra point mass at the link-2 tip (end effector); the controllers do not know it.",
               ("q1", "q2", "tau_m1", "tau_m2", "Z", "T"),
               {"mass": (0.10, "kg", "payload mass")}),
    EffectSpec("ground_effect",
               "Thrust gain near the ground, T (1 + k (R / 4Z)^2) (Cheeseman-Bennett, first "
               "order); the flight hovers at `altitude` so that it matters. No ground contact "
               "model (the arm may dip below Z = 0).",
               ("Z", "T"),
               {"k": (1.0, "1", "gain (1 = Cheeseman-Bennett)"),
                "rotor_radius": (0.127, "m", "propeller radius R"),
                "altitude": (0.6, "m", "hover altitude of the flight")}),
    EffectSpec("thrust_loss",
               "Each rotor's thrust coefficient sagging with the battery: x (1 - c t).",
               ("Z", "T", "tau_phi", "tau_theta"),
               {"c": (0.003, "1/s", "fractional thrust loss per second")}),
    EffectSpec("arm_coupling",
               "The swinging arm's reaction forces and moments on the body (always present in "
               "the simulator; the paper's simplified model (8) treats the arm as extra mass).",
               ("X", "Z", "theta", "tau_theta", "q1", "q2"), {}),
)}


def parse_effect(text: str) -> tuple[str, dict]:
    """``"NAME[:param=value,...]"`` -> (name, {param: value}) with defaults filled in.

    Raises ValueError for an unknown effect, an unknown parameter or a non-numeric value.
    """
    if not isinstance(text, str) or not text.strip():
        raise ValueError("effect: empty effect specification")
    name, _, rest = text.strip().partition(":")
    name = name.strip()
    given = {}
    if rest.strip():
        for item in rest.split(","):
            key, eq, val = item.partition("=")
            if not eq:
                raise ValueError(f"effect {name}: expected param=value, got {item!r}")
            try:
                given[key.strip()] = float(val)
            except ValueError:
                raise ValueError(f"effect {name}: parameter {key.strip()!r}: "
                                 f"not a number: {val.strip()!r}") from None
    return name, _complete(name, given)


def _complete(name: str, given: dict) -> dict:
    spec = EFFECTS.get(name)
    if spec is None:
        raise ValueError(f"effect: unknown effect {name!r} (known: {', '.join(EFFECTS)})")
    out = {k: v[0] for k, v in spec.params.items()}
    for k, v in given.items():
        if k not in spec.params:
            known = ", ".join(spec.params) or "none"
            raise ValueError(f"effect {name}: unknown parameter {k!r} (known: {known})")
        v = float(v)
        if v != v or v in (float("inf"), float("-inf")) or v < 0:
            raise ValueError(f"effect {name}: parameter {k!r} must be finite and >= 0, got {v}")
        out[k] = v
    return out


def resolve_effects(effects, dt: float = 1e-3) -> tuple[dict, dict, dict, dict]:
    """Effects (list of "NAME:..." strings, (name, params) pairs, or a {name: params} dict)
    -> (present {name: params}, plant overrides, control overrides, flight options)."""
    items = []
    if effects is None:
        effects = []
    if isinstance(effects, dict):
        effects = list(effects.items())
    if isinstance(effects, str):
        effects = [effects]
    for e in effects:
        if isinstance(e, str):
            items.append(parse_effect(e))
        elif isinstance(e, (tuple, list)) and len(e) == 2 and isinstance(e[0], str):
            items.append((e[0], _complete(e[0], dict(e[1] or {}))))
        else:
            raise ValueError(f"effects: cannot read {e!r}; use 'NAME[:param=value,...]'")
    present, plant, ctrl, flight = {}, {}, {}, {}
    for name, p in items:
        if name in present:
            raise ValueError(f"effects: {name!r} given twice")
        present[name] = p
        if name == "coulomb_friction":
            plant.update(Fc1=p["Fc1"], Fc2=p["Fc2"], fric_eps=p["eps"])
            if p["eps"] <= 0:
                raise ValueError("effect coulomb_friction: parameter 'eps' must be > 0")
        elif name == "backlash":
            plant.update(backlash1=p["width1"], backlash2=p["width2"])
        elif name == "hardening_stiffness":
            plant.update(K3_1=p["K3_1"], K3_2=p["K3_2"])
        elif name == "actuator_delay":
            ctrl.update(delay_joint=float(round(p["joint"] / dt)), delay_rotor=float(round(p["rotor"] / dt)))
        elif name == "payload_mass":
            plant.update(payload=p["mass"])
        elif name == "ground_effect":
            plant.update(ground_k=p["k"], rotor_radius=p["rotor_radius"])
            flight["altitude"] = p["altitude"]
        elif name == "thrust_loss":
            plant.update(thrust_loss=p["c"])
    present.setdefault("arm_coupling", {})
    return present, plant, ctrl, flight


def describe_effects() -> str:
    """Text for ``cdam simulate --list-effects``."""
    lines = []
    for spec in EFFECTS.values():
        lines.append(f"{spec.name}")
        lines.append(f"    {spec.doc}")
        lines.append(f"    shows on: {', '.join(spec.channels)}")
        if spec.params:
            for k, (d, unit, doc) in spec.params.items():
                lines.append(f"    {k} = {d:g} {unit}  ({doc})")
        else:
            lines.append("    no parameters (always present)")
    return "\n".join(lines)
