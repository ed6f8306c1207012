"""Physical and controller parameters of the simulated aerial manipulator, with their sources.

Two flat float64 vectors cross into the C++ core (``cdam/sim/params.hpp`` reads them in the
same order): the *plant* vector (body, rotors, arm, joints, effects) and the *control* vector
(Pixhawk-like cascades, STM32-like joint PID). Each entry is a :class:`Field` with unit and
source or reasoning. ``plant_vector(**overrides)`` / ``control_vector(**overrides)`` build them.

Frames: world Z up (eq. (1): Z'' = T cos(phi) cos(theta)/m - g); body x forward, y left, z up;
Z-Y-X Euler angles (phi, theta, psi). The arm hangs below the body in the body x-z plane; both
joint axes are parallel to body y; q = 0 is hanging straight down.

X450-like quadrotor (450 mm wheelbase): the mass and inertia are built from a component list
(:data:`BODY_COMPONENTS`), not copied from a paper, so the reasoning is auditable.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Field", "PLANT_FIELDS", "CONTROL_FIELDS", "PLANT_NAMES", "CONTROL_NAMES",
           "plant_vector", "control_vector", "plant_dict", "control_dict", "BODY_COMPONENTS",
           "total_mass", "hover_rotor_speed", "ENCODER_COUNTS", "GEAR_RATIO", "TORQUE_CONSTANT",
           "CURRENT_LSB"]

G = 9.81
L_ARM = 0.225            # m, centre to rotor: half of the 450 mm wheelbase
GEAR_RATIO = 36.0        # M2006 P36 planetary gearbox
ENCODER_COUNTS = 8192    # C610 rotor encoder counts per rotor revolution (before the gearbox)
TORQUE_CONSTANT = 0.18   # N m / A at the gearbox output (DJI M2006 P36 datasheet)
CURRENT_LSB = 0.001      # A: C610 current command, -10000..10000 <-> -10..10 A

# (name, mass kg, geometry): rotors as point masses at the X-frame positions, the rest as a box
BODY_COMPONENTS = {
    "rotor_units": (4 * 0.085, "4 x (920 KV motor 55 g + 20 A ESC 15 g + 10x4.5 prop 15 g) at L"),
    "hub": (1.26, "frame plates 0.28, 3S 4000 mAh battery 0.32, Pixhawk+GPS+RC 0.12, "
                  "2 x M2006 0.18, STM32 board + arm mount 0.36; a 0.18 x 0.18 x 0.10 m box"),
}


def _body_inertia():
    m_rot = BODY_COMPONENTS["rotor_units"][0]
    m_hub = BODY_COMPONENTS["hub"][0]
    a = L_ARM / math.sqrt(2.0)
    w, h = 0.18, 0.10
    jx = m_rot * a * a + m_hub * (w * w + h * h) / 12.0     # 4 masses at |y| = a
    jz = m_rot * L_ARM ** 2 + m_hub * (2 * w * w) / 12.0
    return m_rot + m_hub, jx, jx, jz


_MB, _JX, _JY, _JZ = _body_inertia()


@dataclass(frozen=True)
class Field:
    """One parameter: name, default value, unit and where the value comes from."""

    name: str
    value: float
    unit: str
    source: str


PLANT_FIELDS = (
    # rigid body (eq. (1))
    Field("m_body", _MB, "kg", "sum of BODY_COMPONENTS (X450 class all-up mass without the arm links)"),
    Field("Jx", _JX, "kg m^2", "rotor units as point masses at L/sqrt(2) + hub box"),
    Field("Jy", _JY, "kg m^2", "same as Jx (symmetric X frame)"),
    Field("Jz", _JZ, "kg m^2", "rotor units at L + hub box"),
    Field("Kx", 0.25, "N s/m", "linear drag, typical for a 450 mm frame at < 3 m/s"),
    Field("Ky", 0.25, "N s/m", "as Kx"),
    Field("Kz", 0.30, "N s/m", "slightly larger vertically (disc area)"),
    Field("Kphi", 0.005, "N m s/rad", "rotational air friction, small"),
    Field("Ktheta", 0.005, "N m s/rad", "as Kphi"),
    Field("Kpsi", 0.005, "N m s/rad", "as Kphi"),
    Field("g", G, "m/s^2", "standard gravity"),
    # rotors (eq. (2), X-frame mixer with arm factor L/sqrt(2))
    Field("CT", 1.2e-5, "N s^2/rad^2", "10x4.5 prop: about 12 N at 1000 rad/s (static thrust tables)"),
    Field("CQ", 1.9e-7, "N m s^2/rad^2", "CQ/CT about 0.016 m, typical for 10 inch props"),
    Field("L", L_ARM, "m", "centre-to-rotor distance, half the 450 mm wheelbase"),
    Field("Jm", 3.0e-5, "kg m^2", "prop (about 1.8e-5) + motor bell (about 1.2e-5)"),
    Field("omega_min", 150.0, "rad/s", "idle speed of the ESCs (armed)"),
    Field("omega_max", 1000.0, "rad/s", "3S full throttle, about 9500 rpm"),
    # arm (M(q), C(q, q'), G(q) of a 2-link planar arm hanging below the body)
    Field("d_base", 0.08, "m", "first joint axis below the body centre of mass"),
    Field("m1", 0.12, "kg", "carbon tube link with joint-2 pulley"),
    Field("l1", 0.20, "m", "link 1 length"),
    Field("lc1", 0.10, "m", "link 1 centre of mass from joint 1"),
    Field("I1xx", 4.0e-4, "kg m^2", "m1 l1^2 / 12 (slender rod, perpendicular axis)"),
    Field("I1yy", 4.0e-4, "kg m^2", "m1 l1^2 / 12 about the joint axis through the CoM"),
    Field("I1zz", 1.0e-5, "kg m^2", "along the rod, small"),
    Field("m2", 0.10, "kg", "link 2 with a light gripper"),
    Field("l2", 0.20, "m", "link 2 length (tip = end effector)"),
    Field("lc2", 0.12, "m", "link 2 centre of mass from joint 2 (gripper at the end)"),
    Field("I2xx", 4.0e-4, "kg m^2", "slender rod + gripper"),
    Field("I2yy", 4.0e-4, "kg m^2", "slender rod + gripper, about the joint axis through the CoM"),
    Field("I2zz", 1.0e-5, "kg m^2", "along the rod, small"),
    # flexible joints (eqs. (3)-(5)); motor side after the 36:1 gearbox
    Field("Im1", 1.0e-3, "kg m^2", "M2006 rotor about 8e-7 kg m^2 (25 g, 8 mm radius) x 36^2"),
    Field("Im2", 1.0e-3, "kg m^2", "as Im1"),
    Field("Dm1", 2.0e-3, "N m s/rad", "gearbox viscous loss at the output"),
    Field("Dm2", 2.0e-3, "N m s/rad", "as Dm1"),
    Field("Ks1", 20.0, "N m/rad", "pretensioned cable: 2 k r^2 with k = 4.4e4 N/m, r = 15 mm"),
    Field("Ks2", 15.0, "N m/rad", "longer cable run to joint 2"),
    Field("Kd1", 0.02, "N m s/rad", "cable internal damping"),
    Field("Kd2", 0.02, "N m s/rad", "as Kd1"),
    Field("Dl1", 2.0e-3, "N m s/rad", "link bearing viscous friction (F(q') in eq. (5))"),
    Field("Dl2", 2.0e-3, "N m s/rad", "as Dl1"),
    # effects (all off by default; see cdam_core.sim.effects for meaning and defaults when on)
    Field("Fc1", 0.0, "N m", "effect coulomb_friction: dry friction at motor 1 (after gearbox)"),
    Field("Fc2", 0.0, "N m", "effect coulomb_friction: dry friction at motor 2"),
    Field("fric_eps", 0.05, "rad/s", "Coulomb friction smoothing: Fc tanh(v / eps)"),
    Field("backlash1", 0.0, "rad", "effect backlash: total dead-band width in cable 1"),
    Field("backlash2", 0.0, "rad", "effect backlash: total dead-band width in cable 2"),
    Field("K3_1", 0.0, "N m/rad^3", "effect hardening_stiffness: cubic term of cable 1"),
    Field("K3_2", 0.0, "N m/rad^3", "effect hardening_stiffness: cubic term of cable 2"),
    Field("payload", 0.0, "kg", "effect payload_mass: point mass at the link-2 tip"),
    Field("ground_k", 0.0, "1", "effect ground_effect: T (1 + k (R / 4Z)^2) (Cheeseman-Bennett)"),
    Field("rotor_radius", 0.127, "m", "10 inch propeller radius (ground effect)"),
    Field("thrust_loss", 0.0, "1/s", "effect thrust_loss: each rotor's thrust x (1 - c t)"),
)

CONTROL_FIELDS = (
    Field("m_ctrl", 0.0, "kg", "mass the altitude loop assumes (0: nominal body + links)"),
    Field("kp_pos", 1.0, "1/s", "position P (PX4 MPC_XY_P 0.95)"),
    Field("kp_vel", 2.0, "1/s", "velocity P (PX4 MPC_XY_VEL_P_ACC 1.8)"),
    Field("ki_vel", 0.4, "1/s^2", "velocity I (PX4 MPC_XY_VEL_I_ACC 0.4)"),
    Field("v_max", 2.0, "m/s", "horizontal speed limit"),
    Field("tilt_max", 0.35, "rad", "tilt limit (PX4 MPC_TILTMAX_AIR 20 deg)"),
    Field("kp_z", 1.5, "1/s", "altitude P (PX4 MPC_Z_P 1)"),
    Field("kp_vz", 4.0, "1/s", "climb-rate P (PX4 MPC_Z_VEL_P_ACC 4)"),
    Field("ki_vz", 2.0, "1/s^2", "climb-rate I (PX4 MPC_Z_VEL_I_ACC 2)"),
    Field("kp_att_rp", 6.5, "1/s", "roll/pitch angle P (PX4 MC_ROLL_P 6.5)"),
    Field("kp_att_y", 2.0, "1/s", "yaw angle P (PX4 MC_YAW_P 2.8, softened for the heavy arm)"),
    Field("kp_rate_rp", 25.0, "1/s", "roll/pitch rate P, as angular acceleration per rad/s"),
    Field("ki_rate_rp", 10.0, "1/s^2", "roll/pitch rate I"),
    Field("kd_rate_rp", 0.2, "1", "roll/pitch rate D (on measured rate change)"),
    Field("kp_rate_y", 4.0, "1/s", "yaw rate P (keeps yaw from saturating the rotors)"),
    Field("ki_rate_y", 2.0, "1/s^2", "yaw rate I"),
    Field("rate_max", 3.5, "rad/s", "rate setpoint limit (PX4 MC_ROLLRATE_MAX 220 deg/s)"),
    Field("tau_max", 1.5, "N m", "torque command limit"),
    Field("kp_joint", 3.0, "N m/rad", "STM32 joint PID on the motor angle: P"),
    Field("ki_joint", 4.0, "N m/(rad s)", "joint PID: I"),
    Field("kd_joint", 0.12, "N m s/rad", "joint PID: D on the motor speed (C610 reports it)"),
    Field("tau_m_max", 1.0, "N m", "joint torque limit (M2006 rated output torque)"),
    Field("current_lsb", CURRENT_LSB, "A", "C610 command resolution (0: no quantisation)"),
    Field("kt", TORQUE_CONSTANT, "N m/A", "M2006 P36 torque constant at the output"),
    Field("delay_rotor", 0.0, "samples", "effect actuator_delay: rotor command delay (1 kHz ticks)"),
    Field("delay_joint", 0.0, "samples", "effect actuator_delay: joint command delay (1 kHz ticks)"),
)

PLANT_NAMES = tuple(f.name for f in PLANT_FIELDS)
CONTROL_NAMES = tuple(f.name for f in CONTROL_FIELDS)
_PLANT_DEFAULT = {f.name: f.value for f in PLANT_FIELDS}
_CONTROL_DEFAULT = {f.name: f.value for f in CONTROL_FIELDS}


def _vector(fields, defaults: dict, overrides: dict, what: str) -> np.ndarray:
    out = dict(defaults)
    for k, v in overrides.items():
        if k not in out:
            raise ValueError(f"{what}: unknown parameter {k!r} (known: {', '.join(out)})")
        v = float(v)
        if not math.isfinite(v):
            raise ValueError(f"{k}: must be finite, got {v}")
        out[k] = v
    return np.array([out[f.name] for f in fields], dtype=np.float64)


def plant_vector(**overrides) -> np.ndarray:
    """The plant parameter vector (order of :data:`PLANT_NAMES`) with ``overrides`` applied."""
    return _vector(PLANT_FIELDS, _PLANT_DEFAULT, overrides, "plant")


def control_vector(**overrides) -> np.ndarray:
    """The controller parameter vector (order of :data:`CONTROL_NAMES`)."""
    return _vector(CONTROL_FIELDS, _CONTROL_DEFAULT, overrides, "control")


def plant_dict(vec) -> dict:
    """``{name: value}`` of a plant vector."""
    vec = np.asarray(vec, dtype=float)
    if vec.shape != (len(PLANT_NAMES),):
        raise ValueError(f"plant: expected {len(PLANT_NAMES)} values, got shape {vec.shape}")
    return dict(zip(PLANT_NAMES, vec.tolist()))


def control_dict(vec) -> dict:
    """``{name: value}`` of a control vector."""
    vec = np.asarray(vec, dtype=float)
    if vec.shape != (len(CONTROL_NAMES),):
        raise ValueError(f"control: expected {len(CONTROL_NAMES)} values, got shape {vec.shape}")
    return dict(zip(CONTROL_NAMES, vec.tolist()))


def total_mass(p: dict, with_payload: bool = True) -> float:
    """Body + links (+ payload) mass in kg."""
    return p["m_body"] + p["m1"] + p["m2"] + (p["payload"] if with_payload else 0.0)


def hover_rotor_speed(p: dict) -> float:
    """Rotor speed (rad/s) at which four rotors carry the whole vehicle (no effects)."""
    return math.sqrt(total_mass(p) * p["g"] / (4.0 * p["CT"]))
