"""``run_paper``: the README's main job, from simulated flights to the index page.

Steps: simulate experiments (i) and (ii) and their validation records (:mod:`.records`); smooth
at 1 kHz and decimate to the training rate; identify with IBOA-BP, BOA-BP and CABC-BP over the
seeds as a static input-to-output map (the paper's network), in a second section as a NARX
network and in a third as the hybrid ARX + network model (:mod:`.runner`), scored one-step,
k-step-ahead (:mod:`.kstep`) and free-run, beside the persistence baseline (:mod:`.baseline`);
write the records (CSV + JSON sidecar), predictions.npz, results.json,
the figures (:mod:`.figures`) and index.md / index.html.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from cdam_core.base.folders import FolderError, writable_folder
from cdam_core.base.jsonio import atomic_target, plain, write_text_atomic

from cdam_core.report.paper import figures
from cdam_core.evaluate.baselines import persistence
from cdam_core.report.paper.index import write_index
from cdam_core.report.paper.published import FITNESS, OUTPUTS, RUN_TIME_S, TABLE2, TABLE3
from cdam_core.paper.records import DATA_DESIGN, prepare_data, simulate_records, smoothed
from cdam_core.report.paper.markdown import index_lines
from cdam_core.paper.runner import PaperConfig, run_section
from cdam_core.report.paper.tables import paper_tables, reach_summary

__all__ = ["run_paper", "check_out_dir"]

_SECTION_NAME = {"narx": "NARX", "hybrid": "hybrid ARX + network"}
RECORD_FILES = {"exp_i": "flight_i.csv", "exp_ii": "flight_ii.csv",
                "val_i": "validation_i.csv", "val_ii": "validation_ii.csv"}


def check_out_dir(out) -> Path:
    """Create ``out`` if needed and check it is a writable folder (ValueError otherwise)."""
    try:
        return writable_folder(out, create=True, what="out")
    except FolderError as exc:
        raise ValueError(str(exc)) from None


def _bar(total, enabled):
    from tqdm import tqdm
    return tqdm(total=total, desc="cdam paper", unit="step", file=sys.stderr,
                disable=not enabled, dynamic_ncols=True)


def _figures(d, records, data, sections, preds, best_seeds, smoothing):
    files = {}
    di, dii = records["exp_i"], records["exp_ii"]
    U, Y, Us, Ys = smoothed(di, smoothing)
    oi = [di.outputs.index(n) for n in figures.QUADROTOR]
    figures.preprocessing_figure(di.t, Y[:, oi], Ys[:, oi], figures.QUADROTOR,
                                 d / "fig08_quadrotor_outputs.png",
                                 f"Fig. 8: quadrotor outputs, experiment (i), raw and after "
                                 f"{smoothing} smoothing passes")
    figures.preprocessing_figure(di.t, U[:, :4], Us[:, :4], di.inputs[:4],
                                 d / "fig09_quadrotor_inputs.png",
                                 "Fig. 9: quadrotor inputs, experiment (i), raw and smoothed")
    U, Y, Us, Ys = smoothed(dii, smoothing)
    qi = [dii.outputs.index(n) for n in figures.MANIPULATOR]
    figures.preprocessing_figure(dii.t, np.column_stack([U[:, 4:6], Y[:, qi]]),
                                 np.column_stack([Us[:, 4:6], Ys[:, qi]]),
                                 list(dii.inputs[4:6]) + list(figures.MANIPULATOR),
                                 d / "fig10_manipulator.png",
                                 "Fig. 10: manipulator inputs and outputs, experiment (ii), raw "
                                 "and smoothed")
    files["preprocessing"] = ["fig08_quadrotor_outputs.png", "fig09_quadrotor_inputs.png",
                              "fig10_manipulator.png"]
    figures.convergence_figure(sections, d / "fig11_convergence.png")
    files["convergence"] = ["fig11_convergence.png"]
    number = {("test", "quadrotor"): 12, ("test", "manipulator"): 13,
              ("validation", "quadrotor"): 14, ("validation", "manipulator"): 15}
    files["identified"] = []
    for label, sec in sections.items():
        t0 = sec["t0"]
        modes = ["one_step"] if label == "static" else ["free_run"]
        for rec, segs in (("test", data.test), ("validation", data.validation)):
            seams = [len(segs[0].t) - t0]
            for mode in modes:
                meas = preds[f"{label}/{rec}/{mode}/measured"]
                pred = {a: preds[f"{label}/{rec}/{mode}/{a}/seed{best_seeds[label][a]}"]
                        for a in sec["algorithms"]}
                for part, names in (("quadrotor", figures.QUADROTOR),
                                    ("manipulator", figures.MANIPULATOR)):
                    n = number[(rec, part)]
                    suffix = "" if label == "static" else f"_{label}_{mode}"
                    kind = ("" if label == "static"
                            else f" ({_SECTION_NAME[label]} {mode.replace('_', '-')})")
                    fname = f"fig{n}_{rec}_{part}{suffix}.png"
                    figures.identified_figure(
                        meas, pred, data.outputs, names, data.rate, seams, d / fname,
                        f"Fig. {n}{kind}: identified {part} outputs against actual, {rec} record "
                        "(best seed)")
                    files["identified"].append(fname)
    return files


def run_paper(config: PaperConfig | None = None, out="paper_out", *, progress: bool = True) -> dict:
    """Run the paper's study and write everything into ``out``; returns the results dict
    (the content of results.json)."""
    cfg = config or PaperConfig()
    d = check_out_dir(out)
    t_start = time.perf_counter()
    load_start = os.getloadavg()[0]
    sections_to_run = ([("static", None, "bp")] + ([("narx", cfg.narx, "bp")] if cfg.narx else [])
                       + ([("hybrid", None, "hybrid")] if cfg.hybrid else []))
    bar = _bar(2 + len(sections_to_run) * len(cfg.algos) * cfg.seeds, progress)
    bar.set_postfix_str("simulating flights (i), (ii) and validation records")
    t0 = time.perf_counter()
    records = simulate_records(cfg.flight_seed, cfg.duration, cfg.effects or None)
    data = prepare_data(records, cfg.smoothing, cfg.rate)
    t_sim = time.perf_counter() - t0
    bar.update()
    sections, preds, best_seeds, seconds = {}, {}, {}, {"simulate_and_preprocess": t_sim}
    for label, narx, model in sections_to_run:
        res, p, _ = run_section(data, cfg, narx, bar=bar, label=label, model=model)
        sections[label] = res
        preds.update(p)
        best_seeds[label] = {a: v["best_seed"] for a, v in res["algorithms"].items()}
        seconds[label] = res["seconds"]
    baseline = {}
    for rec, segs in (("test", data.test), ("validation", data.validation)):
        m, arr = persistence(segs, data.outputs, data.rate, cfg.horizons)
        baseline[rec] = m
        for mode, (Ym, Pm) in arr.items():
            preds[f"persistence/{rec}/{mode}/measured"] = Ym
            preds[f"persistence/{rec}/{mode}/predicted"] = Pm
    bar.set_postfix_str("writing records, figures and index")
    t0 = time.perf_counter()
    files = {"records": []}
    from cdam_core.sim import write_flight
    for key, fname in RECORD_FILES.items():
        write_flight(d / fname, records[key])
        files["records"] += [fname, fname.replace(".csv", ".json")]
    with atomic_target(d / "predictions.npz") as tmp:
        np.savez_compressed(tmp, **preds)
    files["predictions"] = "predictions.npz"
    files.update(_figures(d, records, data, sections, preds, best_seeds, cfg.smoothing))
    tables = {label: paper_tables(sec) for label, sec in sections.items()}
    result = {
        "title": "cdam paper: the paper's identification study on simulated flights",
        "config": cfg.to_dict(),
        "data_design": DATA_DESIGN,
        "rate_hz": data.rate,
        "source_rate_hz": float(records["exp_i"].rate),
        "samples": {"train": int(sum(len(s.t) for s in data.train)),
                    "test": int(sum(len(s.t) for s in data.test)),
                    "validation": int(sum(len(s.t) for s in data.validation))},
        "published": {"table2": TABLE2, "table3": TABLE3, "fitness": FITNESS,
                      "run_time_s": RUN_TIME_S, "outputs_order": list(OUTPUTS)},
        "tables": tables,
        "reach": reach_summary(tables),
        "persistence": baseline,
        "rank_sum": {label: sec["rank_sum"] for label, sec in sections.items()},
        "sections": sections,
        "predictions": {"file": "predictions.npz",
                        "t0": {label: sec["t0"] for label, sec in sections.items()},
                        "keys": "SECTION/RECORD/MODE/measured and SECTION/RECORD/MODE/ALGO/seedS;"
                                " the arrays the metrics were computed on (each segment's first "
                                "t0 samples dropped, segments pooled); persistence/RECORD/MODE/"
                                "measured and .../predicted for the baseline y(t) = y(t - k)"},
        "files": files,
    }
    seconds["report"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - t_start
    result["seconds"] = seconds
    result["machine"] = {"cpus": os.cpu_count(), "load_average_1min_start": load_start,
                         "load_average_1min_end": os.getloadavg()[0]}
    lines = index_lines(result)
    md, page = write_index(d, lines, result["title"])
    files["index"] = [md.name, page.name, "results.json"]
    write_text_atomic(d / "results.json", json.dumps(plain(result), indent=1))
    bar.update()
    bar.close()
    return result
