"""Residual analysis: fit a declared grey-box model, find what its residual lacks, add it.

``analyse`` runs the whole loop on arrays; ``cdam residual`` runs it on a dataset file.
"""
from cdam_core.residual.diagnostics import (autocorrelation, cross_correlation, effective_sample_size,
                          ljung_box, spectral_peaks, spectrum, whiteness)
from cdam_core.models.greybox.effects import LIBRARY, Effect, candidates
from cdam_core.models.greybox.estimation import Fit, apply_fit, fit
from cdam_core.models.greybox.freerun import free_run_error, simulate
from cdam_core.models.greybox.flight import AerialManipulator, Quadrotor
from cdam_core.models.greybox.declared import DerivativeFilter, FlexibleJoint, RigidAxis
from cdam_core.models.greybox.registry import get_model
from cdam_core.residual.network import network_residual
from cdam_core.residual.analyse import analyse
from cdam_core.residual.selection import Selection, select

__all__ = ["AerialManipulator", "Quadrotor", "network_residual", "DerivativeFilter", "Effect", "Fit", "FlexibleJoint", "LIBRARY", "RigidAxis",
           "Selection", "analyse", "apply_fit", "autocorrelation", "candidates",
           "cross_correlation", "effective_sample_size", "fit", "free_run_error", "get_model",
           "ljung_box", "select", "simulate", "spectral_peaks", "spectrum",
           "whiteness"]
