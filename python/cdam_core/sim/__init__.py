"""Simulator of the cable-driven aerial manipulator (issue 3).

The physics and loops run in the C++ core (``cdam/sim/``); :mod:`.reference` is the numpy twin.

>>> from cdam_core.sim import simulate_flight
>>> ds = simulate_flight("i", duration=2.0, seed=1)      # doctest: +SKIP
>>> ds.columns[:6]                                       # doctest: +SKIP
['T', 'tau_phi', 'tau_theta', 'tau_psi', 'tau_m1', 'tau_m2']
"""
from cdam_core.sim.effects import EFFECTS, describe_effects, parse_effect, resolve_effects
from cdam_core.sim.flight import run_closed_loop, simulate_flight, substeps_for, validation_seed, write_flight
from cdam_core.sim.parameters import CONTROL_FIELDS, PLANT_FIELDS, control_vector, plant_vector

__all__ = ["EFFECTS", "describe_effects", "parse_effect", "resolve_effects", "run_closed_loop",
           "simulate_flight", "substeps_for", "validation_seed", "write_flight", "CONTROL_FIELDS",
           "PLANT_FIELDS", "control_vector", "plant_vector"]
