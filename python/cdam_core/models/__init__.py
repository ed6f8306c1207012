"""Every identified model kind, one protocol (:mod:`.protocol`) and one file (:mod:`.file`).

Kinds: ``bp_network`` (:class:`BPNetwork`, static or NARX), ``arx`` (:class:`ArxModel`),
``hybrid`` (:class:`HybridNarx`: ARX + network on its residual), ``greybox`` (the declared
grey-box model plus the effects the residual loop found, :mod:`.greybox`), ``arx_kstep``
(:class:`ArxKStep`: ARX + recurrent network on its k-step residual, trained on the k-step
error), ``arx_direct`` (:class:`ArxDirect`: one least-squares fit per prediction step on the
ARX's regressors over the step's window), ``kstep_blend`` (:class:`KStepBlend`: fitted models blended per prediction step and
group of outputs), the flight models (:mod:`.flight`).
"""
from cdam_core.models.arx import ArxModel, physics_features
from cdam_core.models.arx_direct import ArxDirect
from cdam_core.models.arx_kstep import ArxKStep
from cdam_core.models.flight.hybrid import QuadHybrid
from cdam_core.models.flight.physics import QuadPhysics
from cdam_core.models.file import KINDS, ModelFile, load_model, read_model_file, save_model
from cdam_core.models.hybrid import HybridNarx
from cdam_core.models.kstep_blend import KStepBlend
from cdam_core.models.network import BPNetwork, hidden_node_candidates
from cdam_core.models.protocol import Model, segment_bounds

__all__ = ["ArxDirect", "ArxKStep", "ArxModel", "BPNetwork", "HybridNarx", "KINDS", "KStepBlend", "Model",
           "ModelFile",
           "QuadHybrid", "QuadPhysics", "hidden_node_candidates", "load_model", "physics_features",
           "read_model_file", "save_model", "segment_bounds"]
