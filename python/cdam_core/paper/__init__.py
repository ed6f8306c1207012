"""``cdam paper``: the paper's identification study (Tables 2 and 3, Figs. 8-15) on simulated
flights, with a NARX-network section and a hybrid (linear ARX + network) section scored
one-step, k-step-ahead and free-run, a persistence baseline, beside the published values.

>>> from cdam_core.paper import PaperConfig, run_paper
>>> result = run_paper(PaperConfig(seeds=4), "paper_out")    # doctest: +SKIP
"""
from cdam_core.paper.pipeline import check_out_dir, run_paper
from cdam_core.report.paper.published import FITNESS, RUN_TIME_S, TABLE2, TABLE3
from cdam_core.evaluate.baselines import persistence
from cdam_core.evaluate.kstep import horizon_steps, k_step_predict
from cdam_core.paper.records import DATA_DESIGN, prepare_data, simulate_records
from cdam_core.paper.runner import PaperConfig, evaluate_segments, run_section

__all__ = ["DATA_DESIGN", "FITNESS", "PaperConfig", "RUN_TIME_S", "TABLE2", "TABLE3",
           "check_out_dir", "evaluate_segments", "horizon_steps", "k_step_predict", "persistence",
           "prepare_data", "run_paper", "run_section", "simulate_records"]
