"""Flights of experiments (i) and (ii): closed-loop simulation, measurement, dataset output.

``simulate_flight`` runs the C++ core (the numpy twin, :mod:`cdam_core.reference.simulator`,
checks it in the tests) and returns a :class:`cdam_core.record.dataset.Dataset`.
Seeds: the excitation draws from ``numpy.random.default_rng([seed, 1])``, the sensor noise from
``default_rng([seed, 2])``. The validation record uses seed ``(seed + 1000003) mod 2**32`` and
lasts 10 s unless ``duration`` is given.
"""
from __future__ import annotations

import math

import numpy as np

from cdam_core.record.dataset import Dataset, STANDARD_INPUTS, STANDARD_OUTPUTS, write_dataset
from cdam_core.sim.effects import EFFECTS, resolve_effects
from cdam_core.sim.excitation import CHANNELS, experiment_setpoints
from cdam_core.sim.measurement import ENCODER_COUNTS, LINK_ENCODER_COUNTS, NOISE_STD, measure
from cdam_core.sim.state import hover_state
from cdam_core.sim.parameters import (CONTROL_NAMES, control_vector, plant_dict, plant_vector)

__all__ = ["simulate_flight", "run_closed_loop", "substeps_for", "validation_seed", "write_flight"]

VALIDATION_SEED_OFFSET = 1000003
BATTERY_FULL = 12.6  # V, 3S


def validation_seed(seed: int) -> int:
    """Seed of the validation record of a flight with ``seed``."""
    return (int(seed) + VALIDATION_SEED_OFFSET) % 2 ** 32


def substeps_for(plant, dt: float) -> int:
    """RK4 sub-steps per ``dt`` so that h * fastest motor-side rate <= 2.5 (numpy twin of
    ``cdam::sim::substeps_for``; the rate bound is documented in ``cdam/sim/simulator.hpp``)."""
    P = plant_dict(plant)
    rate = 0.0
    for k in (1, 2):
        ks = P[f"Ks{k}"] + 3.0 * abs(P[f"K3_{k}"]) * 0.2 ** 2
        damp = P[f"Dm{k}"] + P[f"Kd{k}"] + (abs(P[f"Fc{k}"]) / P["fric_eps"] if P["fric_eps"] > 0 else 0)
        rate = max(rate, math.sqrt(ks / P[f"Im{k}"]), damp / P[f"Im{k}"])
    return max(1, math.ceil(dt * rate / 2.5))


def run_closed_loop(plant, control, x0, setpoints, dt=1e-3, substeps=None):
    """(states (N, 21), log (N, 10)) of a closed-loop flight; see ``cdam/sim/simulator.hpp``."""
    plant = np.asarray(plant, dtype=np.float64)
    control = np.asarray(control, dtype=np.float64)
    if substeps is None:
        substeps = substeps_for(plant, dt)
    from cdam_core import _core
    return _core.sim_closed_loop(plant, control, np.asarray(x0, float),
                                 np.ascontiguousarray(setpoints, dtype=np.float64), dt, substeps)


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"seed: expected an integer, got {seed!r}")
    if not 0 <= int(seed) < 2 ** 32:
        raise ValueError("seed: must be in 0 .. 2**32-1")
    return int(seed)


def simulate_flight(experiment: str = "i", duration: float | None = None, seed: int = 0,
                    effects=None, validation: bool = False, declare=(), noise_scale: float = 1.0,
                    dt: float = 1e-3, plant_overrides: dict | None = None,
                    control_overrides: dict | None = None) -> Dataset:
    """Simulate one logged flight and return it as a Dataset (columns: the standard inputs and
    outputs, theta_m1, theta_m2, omega1..4, battery_v; sidecar metadata in ``meta``).

    Args:
        experiment: "i" (arm held, attitude and altitude excited), "ii" (hovering, joints
            excited) or "both" (all channels at once).
        duration: seconds (default 20, or 10 for ``validation``).
        seed: integer in 0 .. 2**32-1; same seed, same record.
        effects: effects present in the physics ("NAME[:param=value,...]" strings, (name,
            params) pairs or a {name: params} dict); see ``cdam_core.sim.effects``.
        validation: the separate validation record (its own seed, see :func:`validation_seed`).
        declare: effect names declared in the sidecar's model (others stay hidden).
        noise_scale: multiplies every sensor noise standard deviation.
        dt: logging and control period (s).
    """
    seed = _check_seed(seed)
    if duration is None:
        duration = 10.0 if validation else 20.0
    duration = float(duration)
    if not math.isfinite(duration) or duration <= 0:
        raise ValueError(f"duration: must be positive and finite, got {duration}")
    if not (math.isfinite(dt) and 0 < dt <= 0.1):
        raise ValueError(f"dt: must be in (0, 0.1] s, got {dt}")
    if isinstance(declare, str):
        declare = [declare]
    present, plant_over, ctrl_over, flight = resolve_effects(effects, dt)
    for name in declare:
        if name not in EFFECTS:
            raise ValueError(f"declare: unknown effect {name!r} (known: {', '.join(EFFECTS)})")
    plant_over.update(plant_overrides or {})
    ctrl_over.update(control_overrides or {})
    plant = plant_vector(**plant_over)
    control = control_vector(**ctrl_over)
    run_seed = validation_seed(seed) if validation else seed
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    altitude = flight.get("altitude", 1.0)
    sp = experiment_setpoints(experiment, t, np.random.default_rng([run_seed, 1]), altitude)
    x0 = hover_state(Z=altitude)
    substeps = substeps_for(plant, dt)
    states, log = run_closed_loop(plant, control, x0, sp, dt, substeps)
    if not np.all(np.isfinite(states)):
        raise ValueError("simulation diverged (non-finite state); check the parameters")
    cols = measure(states, log, np.random.default_rng([run_seed, 2]), noise_scale)
    P = plant_dict(plant)
    cols["battery_v"] = BATTERY_FULL * np.sqrt(np.maximum(1.0 - P["thrust_loss"] * t, 0.0))
    names = list(STANDARD_INPUTS) + list(STANDARD_OUTPUTS) + [
        "theta_m1", "theta_m2", "omega1", "omega2", "omega3", "omega4", "battery_v"]
    data = np.column_stack([cols[c] for c in names])
    declared = sorted(set(declare))
    meta = {
        "source": "cdam simulate (cdam_core.sim)",
        "experiment": experiment,
        "validation": bool(validation),
        "seed": seed,
        "record_seed": run_seed,
        "duration": duration,
        "rate": 1.0 / dt,
        "units": {"omega1": "rad/s", "omega2": "rad/s", "omega3": "rad/s", "omega4": "rad/s",
                  "battery_v": "V"},
        "model": {"name": "aerial_manipulator",
                  "form": "paper (8): quadrotor (1)-(2) with the arm as extra mass, plus the "
                          "flexible joints (3)-(5)",
                  "effects": declared},
        "effects": present,
        "undeclared_effects": sorted(set(present) - set(declared)),
        "noise": {"std": {k: v * noise_scale for k, v in NOISE_STD.items()},
                  "noise_scale": noise_scale,
                  "motor_encoder_counts_per_rotor_rev": ENCODER_COUNTS,
                  "gear_ratio": 36.0, "link_encoder_counts": LINK_ENCODER_COUNTS,
                  "current_lsb_A": float(control[CONTROL_NAMES.index("current_lsb")])},
        "parameters": {"plant": P, "control": dict(zip(CONTROL_NAMES, control.tolist()))},
        "setpoint_channels": list(CHANNELS),
        "integrator": {"method": "RK4", "dt": dt, "substeps": substeps,
                       "criterion": "h * max_k max(sqrt(Ks_eff/Im), (Dm+Kd+Fc/eps)/Im) <= 2.5"},
        "inputs": list(STANDARD_INPUTS),
        "outputs": list(STANDARD_OUTPUTS),
    }
    return Dataset(t=t, columns=names, data=data, meta=meta)


def write_flight(path, dataset: Dataset) -> None:
    """Write a simulated flight in the dataset format (CSV + JSON sidecar)."""
    write_dataset(path, dataset)
