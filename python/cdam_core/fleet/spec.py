"""The batch spec: a JSON object naming a command, a glob of records and the grid to run.

    {"command": "identify",                  # identify | evaluate | crossfold
     "records": ["flights/*.csv"],           # globs, relative to the current folder;
                                             # "shared:nanodrone/*.parquet": in the shared
                                             # data folder (record.realdata.shared_data_dir)
     "algorithms": ["iboa", "bp"],           # identify only (default ["iboa"])
     "seeds": 10,                            # identify: seed indices 0..N-1 (default 1)
     "seed_rule": "index",                   # index: seed = index (as `cdam identify --seeds`);
                                             # derived: uint32 from (record, algorithm, index, fold)
     "folds": 1,                             # identify: forward-chaining folds (below);
                                             # crossfold: list of test types (default all four)
     "model": "model.json",                  # evaluate only: the model file scored on each record
     "options": {...}}                       # the command's options (OPTIONS below)

Records are stored as absolute paths, so that workers started elsewhere (a `dask worker`
on another machine sharing the file system) read the same files.

Tasks are the product records x algorithms x seed indices x folds, in that order; a task's
seed depends on the task alone (never on the worker that runs it), so any number of workers
gives the serial answer.

Folds of ``identify``: with ``folds`` = 1 the first ``split`` of the record trains and the
rest tests (as ``cdam identify --split``); with K > 1 the record is cut into K + 1 equal blocks
and fold k trains on blocks 0..k and tests on block k + 1 (forward chaining, as scikit-learn's
``TimeSeriesSplit``: training always precedes the test and stays contiguous, which a NARX
network needs).
"""
from __future__ import annotations

import glob
import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["BatchSpec", "Task", "load_spec", "parse_spec", "derived_seed", "COMMANDS", "OPTIONS"]

COMMANDS = ("identify", "evaluate", "crossfold")
ALGORITHMS = ("iboa", "boa", "cabc", "bp")
CROSSFOLD_TYPES = ("square", "random1", "random2", "multisine")

# option: (default, commands that take it)
OPTIONS = {
    "hidden": (20, ("identify",)), "narx": (None, ("identify",)),
    "smoothing": (5, ("identify",)), "iterations": (50, ("identify",)),
    "population": (20, ("identify",)), "epochs": (50, ("identify",)),
    "goal": (0.003, ("identify",)), "model": ("bp", ("identify",)),
    "features": ("raw", ("identify",)), "split": (0.5, ("identify",)),
    "threads": (1, ("identify",)),
    "inputs": (None, ("identify", "evaluate")), "outputs": (None, ("identify", "evaluate")),
    "map": (None, ("identify", "evaluate")), "nan": ("error", ("identify", "evaluate")),
    "loader": ("dataset", ("identify", "evaluate")),
    "horizon": (None, ("identify", "evaluate", "crossfold")),
}


@dataclass(frozen=True)
class Task:
    """One unit of work: ``index`` in the task list, the command, the record path(s) it reads,
    algorithm, seed index and seed, fold (None where the command has none)."""

    index: int
    command: str
    records: tuple
    algorithm: str | None
    seed_index: int | None
    seed: int | None
    fold: object
    options: dict = field(default_factory=dict, hash=False, compare=False)
    model_file: str | None = None

    @property
    def record(self) -> str:
        return self.records[0] if len(self.records) == 1 else ";".join(self.records)

    @property
    def key(self) -> str:
        """A name for the task's files and Dask key: index, record stem, algorithm, seed, fold."""
        parts = [f"{self.index:04d}", Path(self.records[0]).stem if len(self.records) == 1
                 else "all"]
        if self.algorithm:
            parts.append(self.algorithm)
        if self.seed_index is not None:
            parts.append(f"s{self.seed_index}")
        if self.fold is not None:
            parts.append(f"f{self.fold}")
        return "-".join("".join(c if c.isalnum() or c in "._" else "_" for c in p)
                        for p in parts)


@dataclass
class BatchSpec:
    command: str
    records: list[str]
    algorithms: list[str]
    seeds: int
    seed_rule: str
    folds: list
    model: str | None
    options: dict
    source: dict

    def tasks(self) -> list[Task]:
        out = []
        if self.command == "crossfold":
            for fold in self.folds:
                out.append(Task(len(out), "crossfold", tuple(self.records), None, None, None,
                                fold, self.options))
            return out
        algos = self.algorithms if self.command == "identify" else [None]
        seeds = range(self.seeds) if self.command == "identify" else [None]
        for rec in self.records:
            for algo in algos:
                for s in seeds:
                    for fold in self.folds:
                        seed = None if s is None else (
                            s if self.seed_rule == "index" else
                            derived_seed(Path(rec).name, algo, s, fold))
                        out.append(Task(len(out), self.command, (rec,), algo, s, seed, fold,
                                        self.options, self.model))
        return out


def derived_seed(record: str, algorithm, seed_index: int, fold) -> int:
    """A uint32 from the task alone: the first 4 bytes (little endian) of the sha256 of
    'record|algorithm|seed_index|fold'."""
    text = f"{record}|{algorithm}|{seed_index}|{fold}".encode()
    return int.from_bytes(hashlib.sha256(text).digest()[:4], "little")


def load_spec(path, base=".") -> BatchSpec:
    """Read and check a spec file (JSON); globs are relative to ``base`` (default: the
    current folder)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    return parse_spec(doc, base=base)


def _int(doc, name, default, low):
    v = doc.get(name, default)
    if isinstance(v, bool) or not isinstance(v, int) or v < low:
        raise ValueError(f"spec.{name}: must be an integer >= {low}, got {v!r}")
    return v


def parse_spec(doc, base=".") -> BatchSpec:
    """A :class:`BatchSpec` from a decoded spec (module doc); ValueError naming the field."""
    if not isinstance(doc, dict):
        raise ValueError("spec: expected a JSON object")
    unknown = set(doc) - {"command", "records", "algorithms", "seeds", "seed_rule", "folds",
                          "model", "options"}
    if unknown:
        raise ValueError(f"spec: unknown field(s) {', '.join(sorted(unknown))}")
    command = doc.get("command")
    if command not in COMMANDS:
        raise ValueError(f"spec.command: must be one of {', '.join(COMMANDS)}, got {command!r}")
    base = Path(base)
    globs = doc.get("records")
    if isinstance(globs, str):
        globs = [globs]
    if not isinstance(globs, list) or not globs or not all(isinstance(g, str) for g in globs):
        raise ValueError("spec.records: expected a glob or a non-empty list of globs")
    records = []
    for g in globs:
        if g.startswith("shared:"):
            from cdam_core.record.realdata import shared_data_dir
            pattern = str(shared_data_dir() / g[len("shared:"):])
        else:
            pattern = g if Path(g).is_absolute() else str(base / g)
        found = sorted(glob.glob(pattern))
        if not found:
            raise ValueError(f"spec.records: {g!r} matches no file (from {base})")
        records += [f for f in map(os.path.abspath, found) if f not in records]
    algorithms = doc.get("algorithms", ["iboa"])
    if isinstance(algorithms, str):
        algorithms = [algorithms]
    if (not isinstance(algorithms, list) or not algorithms
            or any(a not in ALGORITHMS for a in algorithms)):
        raise ValueError(f"spec.algorithms: expected a list of {', '.join(ALGORITHMS)}, "
                         f"got {algorithms!r}")
    seeds = _int(doc, "seeds", 1, 1)
    seed_rule = doc.get("seed_rule", "index")
    if seed_rule not in ("index", "derived"):
        raise ValueError(f"spec.seed_rule: must be 'index' or 'derived', got {seed_rule!r}")
    if command == "crossfold":
        folds = doc.get("folds", list(CROSSFOLD_TYPES))
        if (not isinstance(folds, list) or not folds
                or any(f not in CROSSFOLD_TYPES for f in folds)):
            raise ValueError(f"spec.folds: crossfold takes a list of test types "
                             f"({', '.join(CROSSFOLD_TYPES)}), got {folds!r}")
    elif command == "identify":
        folds = list(range(_int(doc, "folds", 1, 1)))
    else:
        if "folds" in doc:
            raise ValueError("spec.folds: evaluate has no folds")
        folds = [None]
    model = doc.get("model")
    if command == "evaluate":
        if not isinstance(model, str):
            raise ValueError("spec.model: evaluate needs the model file")
        model = os.path.abspath(model if Path(model).is_absolute() else base / model)
        if not Path(model).is_file():
            raise ValueError(f"spec.model: no such file {model!r}")
    elif model is not None:
        raise ValueError(f"spec.model: only evaluate takes a model file, not {command}")
    options = doc.get("options", {})
    if not isinstance(options, dict):
        raise ValueError("spec.options: expected a JSON object")
    for k in options:
        if k not in OPTIONS or command not in OPTIONS[k][1]:
            raise ValueError(f"spec.options.{k}: not an option of {command}")
    opts = {k: options.get(k, d) for k, (d, cmds) in OPTIONS.items() if command in cmds}
    if command == "identify":
        opts["folds"] = len(folds)
    if command == "identify":
        split = opts["split"]
        if isinstance(split, bool) or not isinstance(split, (int, float)) or not 0 < split < 1:
            raise ValueError(f"spec.options.split: must be in (0, 1), got {split!r}")
    h = opts.get("horizon")
    if h is not None and (isinstance(h, bool) or not isinstance(h, int) or h < 1):
        raise ValueError(f"spec.options.horizon: must be an integer >= 1, got {h!r}")
    return BatchSpec(command, records, list(algorithms), seeds, seed_rule, folds, model, opts,
                     dict(doc))
