"""System identification with BP networks seeded by BOA, IBOA or CABC (the paper's pipelines).

- :func:`identify` runs one pipeline (preprocess, optimise initial weights in C++, LM refine);
- :func:`evaluate` computes per-output Pearson r, RMSE, NRMSE (one-step and NARX free-run);
- :class:`HybridNarx` (``IdentifyConfig(model="hybrid")``): linear ARX + network on its
  residual, raw or physics features; :func:`select_structure` picks orders by validation;
- :func:`compare` runs algorithms x seeds with a rank-sum test; :func:`write_report` writes the
  Markdown report with PNG figures.
The reported "fitness" is the adaptation value 1 / (1 + MSE), MSE in normalised units.
"""
from .compare import compare, rank_sum, summarise
from .hybrid import HybridNarx, physics_features, select_structure
from .metrics import adaptation_value, nrmse, output_metrics, pearson_r, rmse
from .pipelines import ALGORITHMS, IdentifyConfig, IdentifyRun, evaluate, identify, preprocess

__all__ = ["ALGORITHMS", "HybridNarx", "IdentifyConfig", "IdentifyRun", "adaptation_value", "compare",
           "evaluate", "identify", "nrmse", "output_metrics", "pearson_r", "preprocess",
           "physics_features", "rank_sum", "rmse", "select_structure", "summarise",
           "write_report"]


def __getattr__(name):
    if name == "write_report":  # matplotlib only when a report is written
        from .report import write_report
        return write_report
    raise AttributeError(f"module 'cdam_core.identify' has no attribute {name!r}")
