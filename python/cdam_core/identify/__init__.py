"""System identification with BP networks seeded by BOA, IBOA or CABC (the paper's pipelines).

- :func:`identify` runs one pipeline (preprocess, optimise initial weights in C++, LM refine);
  ``IdentifyConfig(model="hybrid")`` fits a linear ARX + the algorithm's network on its
  residual (:class:`cdam_core.models.HybridNarx`);
- :func:`select_structure` picks ARX orders, delay and features by validation;
The reported "fitness" is the adaptation value 1 / (1 + MSE), MSE in normalised units.
Scoring on records and the algorithms x seeds comparison are the next stage,
:mod:`cdam_core.evaluate`; reports are
:mod:`cdam_core.report`.
"""
from cdam_core.identify.pipelines import ALGORITHMS, IdentifyConfig, IdentifyRun, identify, preprocess
from cdam_core.identify.structure import select_structure

__all__ = ["ALGORITHMS", "IdentifyConfig", "IdentifyRun", "identify", "preprocess",
           "select_structure"]
