"""Residual analysis: fit a declared grey-box model, find what its residual lacks, add it.

``analyse`` runs the whole loop on arrays; ``cdam residual`` runs it on a dataset file.
"""
from .diagnostics import (autocorrelation, cross_correlation, effective_sample_size,
                          ljung_box, spectral_peaks, spectrum, whiteness)
from .effects import LIBRARY, Effect, candidates
from .estimation import Fit, apply_fit, fit, free_run_error, simulate
from .flight_models import AerialManipulator, Quadrotor
from .models import DerivativeFilter, FlexibleJoint, RigidAxis, get_model
from .network import network_residual
from .report import analyse, to_json, write_report
from .selection import Selection, select

__all__ = ["AerialManipulator", "Quadrotor", "network_residual", "DerivativeFilter", "Effect", "Fit", "FlexibleJoint", "LIBRARY", "RigidAxis",
           "Selection", "analyse", "apply_fit", "autocorrelation", "candidates",
           "cross_correlation", "effective_sample_size", "fit", "free_run_error", "get_model",
           "ljung_box", "select", "simulate", "spectral_peaks", "spectrum", "to_json",
           "whiteness", "write_report"]
