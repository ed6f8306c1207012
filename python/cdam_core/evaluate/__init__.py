"""Evaluate: score fitted models on records (metrics, k-step prediction, naive baselines)."""
from cdam_core.evaluate.baselines import persistence
from cdam_core.evaluate.compare import Comparison, compare, rank_sum, summarise
from cdam_core.evaluate.kstep import horizon_steps, k_step_predict
from cdam_core.evaluate.scores import evaluate

__all__ = ["Comparison", "compare", "evaluate", "rank_sum", "summarise", "horizon_steps", "k_step_predict", "persistence"]
