"""The batch spec: a JSON object naming a command, a glob of records and the grid to run.

    {"command": "identify",                  # identify | evaluate | crossfold | residual |
                                             # paper
     "records": ["flights/*.csv"],           # globs, relative to the current folder;
                                             # "shared:nanodrone/*.parquet": in the shared
                                             # data folder (record.realdata.shared_data_dir)
     "algorithms": ["iboa", "bp"],           # identify (default ["iboa"]), paper (default
                                             # the paper's ["iboa", "boa", "cabc"])
     "seeds": 10,                            # identify, paper: seed indices 0..N-1 (default 1)
     "seed_rule": "index",                   # index: seed = index (as `cdam identify --seeds`);
                                             # derived: uint32 from (record, algorithm, index, fold)
     "folds": 1,                             # identify: forward-chaining folds (below);
                                             # crossfold: list of test types (default all four)
     "model": "model.json",                  # evaluate only: the model file scored on each record
     "sections": ["static", "narx", "hybrid"],   # paper only (default: all three)
     "options": {...}}                       # the command's options (OPTIONS below)

``paper`` is `cdam paper`'s comparison as tasks (no ``records``: each worker simulates the
flights from ``options.flight_seed``, as `cdam paper` does, and keeps them for its next tasks):
one task per section x algorithm x seed, in `cdam paper`'s order, each running
``cdam_core.paper.runner.run_seed``, the code path of `cdam paper` itself; its options are
``PaperConfig``'s fields (PAPER_OPTIONS). ``residual`` runs `cdam residual`'s analysis on each
record (RESIDUAL_OPTIONS: the greybox ``model`` is required).

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
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["BatchSpec", "Task", "load_spec", "parse_spec", "derived_seed", "COMMANDS", "OPTIONS"]

COMMANDS = ("identify", "evaluate", "crossfold", "residual", "paper")
ALGORITHMS = ("iboa", "boa", "cabc", "bp")
CROSSFOLD_TYPES = ("square", "random1", "random2", "multisine")
SECTIONS = ("static", "narx", "hybrid")
PAPER_ALGORITHMS = ("iboa", "boa", "cabc")

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
# residual: `cdam residual`'s options ("map" and "fixed" as JSON objects, "inputs" a list)
RESIDUAL_OPTIONS = {"model": None, "inputs": None, "outputs": None, "map": None, "fixed": None,
                    "cutoff": None, "alpha": 0.01, "free_run": True, "estimator": "auto",
                    "output_error": False, "stick_slip": "auto"}
RESIDUAL_MODELS = ("rigid_axis", "flexible_joint", "quadrotor", "aerial_manipulator")
# paper: option -> PaperConfig field (defaults: PaperConfig's, except threads: 1, as identify's
# tasks, since the workers already fill the cores)
PAPER_OPTIONS = {"flight_seed": "flight_seed", "duration": "duration", "rate": "rate",
                 "smoothing": "smoothing", "hidden": "hidden", "population": "population",
                 "iterations": "iterations", "epochs": "lm_epochs", "goal": "lm_goal",
                 "switch_probability": "switch_probability", "cabc_limit": "cabc_limit",
                 "narx": "narx", "horizons": "horizons", "threads": "threads",
                 "effects": "effects"}


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
    section: str | None = None

    @property
    def record(self) -> str:
        return self.records[0] if len(self.records) == 1 else ";".join(self.records)

    @property
    def key(self) -> str:
        """A name for the task's files and Dask key: index, record stem, algorithm, seed, fold."""
        parts = [f"{self.index:04d}", Path(self.records[0]).stem if len(self.records) == 1
                 else "all"]
        if self.section:
            parts.append(self.section)
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
    sections: list = field(default_factory=list)

    def tasks(self) -> list[Task]:
        out = []
        if self.command == "paper":
            for sec in self.sections:
                for algo in self.algorithms:
                    for s in range(self.seeds):
                        seed = (s if self.seed_rule == "index" else
                                derived_seed(self.records[0], algo, s, sec))
                        out.append(Task(len(out), "paper", tuple(self.records), algo, s, seed,
                                        None, self.options, None, sec))
            return out
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


def _records(doc, base: Path) -> list[str]:
    globs = doc.get("records")
    if isinstance(globs, str):
        globs = [globs]
    if not isinstance(globs, list) or not globs or not all(isinstance(g, str) for g in globs):
        raise ValueError("spec.records: expected a glob or a non-empty list of globs")
    records = []
    for g in globs:
        where = f"from {base}"
        if g.startswith("shared:"):
            from cdam_core.record.realdata import shared_data_dir
            shared = shared_data_dir()
            pattern = str(shared / g[len("shared:"):])
            where = (f"in the shared data folder {shared}, set by CDAM_SHARED_DATA, else "
                     "../shared/data beside the checkout: these records are not in the "
                     "repository")
        else:
            pattern = g if Path(g).is_absolute() else str(base / g)
        found = sorted(glob.glob(pattern))
        if not found:
            raise ValueError(f"spec.records: {g!r} matches no file ({where})")
        records += [f for f in map(os.path.abspath, found) if f not in records]
    return records


def _list(doc, name, default, allowed):
    v = doc.get(name, list(default))
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v or any(a not in allowed for a in v) \
            or len(set(v)) != len(v):
        raise ValueError(f"spec.{name}: expected a list of distinct {', '.join(allowed)}, "
                         f"got {v!r}")
    return list(v)


def _paper_options(options: dict, sections: list) -> dict:
    """PaperConfig's fields from the spec's options (PAPER_OPTIONS), checked by PaperConfig."""
    from dataclasses import fields

    from cdam_core.paper.runner import PaperConfig
    defaults = {f.name: f.default for f in fields(PaperConfig) if f.name in
                PAPER_OPTIONS.values() and f.name != "effects"}
    opts = {k: options.get(k, defaults.get(f, [] if f == "effects" else None))
            for k, f in PAPER_OPTIONS.items()}
    if "threads" not in options:
        opts["threads"] = 1
    for k in ("narx", "horizons", "effects"):
        if opts[k] is not None and not isinstance(opts[k], (list, tuple)):
            raise ValueError(f"spec.options.{k}: expected a list, got {opts[k]!r}")
    opts["narx"] = None if opts["narx"] is None else list(opts["narx"])
    opts["horizons"] = list(opts["horizons"])
    opts["effects"] = list(opts["effects"])
    try:
        PaperConfig(**{PAPER_OPTIONS[k]: v for k, v in opts.items()})
    except (TypeError, ValueError) as exc:
        raise ValueError(f"spec.options: {' '.join(str(exc).split())}") from None
    if "narx" in sections and opts["narx"] is None:
        raise ValueError("spec.sections: 'narx' needs options.narx (the orders)")
    return opts


def _residual_options(options: dict) -> dict:
    opts = {k: options.get(k, d) for k, d in RESIDUAL_OPTIONS.items()}
    if opts["model"] not in RESIDUAL_MODELS:
        raise ValueError(f"spec.options.model: residual needs one of "
                         f"{', '.join(RESIDUAL_MODELS)}, got {opts['model']!r}")
    for k in ("map", "fixed"):
        v = opts[k]
        if v is not None and (not isinstance(v, dict)
                              or not all(isinstance(x, str) for x in v)):
            raise ValueError(f"spec.options.{k}: expected a JSON object, got {v!r}")
    if opts["fixed"] and not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                 for x in opts["fixed"].values()):
        raise ValueError(f"spec.options.fixed: expected numbers, got {opts['fixed']!r}")
    if opts["map"] and not all(isinstance(x, str) for x in opts["map"].values()):
        raise ValueError(f"spec.options.map: expected column names, got {opts['map']!r}")
    for k in ("inputs", "outputs"):
        v = opts[k]
        if v is not None and (not isinstance(v, list) or not all(isinstance(x, str) for x in v)):
            raise ValueError(f"spec.options.{k}: expected a list of column names, got {v!r}")
    a = opts["alpha"]
    if isinstance(a, bool) or not isinstance(a, (int, float)) or not 0 < a < 1:
        raise ValueError(f"spec.options.alpha: must be in (0, 1), got {a!r}")
    c = opts["cutoff"]
    if c is not None and (isinstance(c, bool) or not isinstance(c, (int, float))
                          or not math.isfinite(c) or c <= 0):
        raise ValueError(f"spec.options.cutoff: must be a positive frequency in Hz, got {c!r}")
    for k in ("free_run", "output_error"):
        if not isinstance(opts[k], bool):
            raise ValueError(f"spec.options.{k}: must be true or false, got {opts[k]!r}")
    if opts["estimator"] not in ("auto", "idim-ls", "idim-iv", "oe", "sim"):
        raise ValueError(f"spec.options.estimator: expected auto, idim-ls, idim-iv, oe or sim, got "
                         f"{opts['estimator']!r}")
    if opts["stick_slip"] not in ("auto", "on", "off"):
        raise ValueError(f"spec.options.stick_slip: expected auto, on or off, got "
                         f"{opts['stick_slip']!r}")
    if opts["output_error"]:   # the older spelling of estimator "oe"
        if opts["estimator"] not in ("auto", "oe"):
            raise ValueError(f"spec.options.output_error: conflicts with estimator "
                             f"{opts['estimator']!r}")
        opts["estimator"] = "oe"
    return opts


def parse_spec(doc, base=".") -> BatchSpec:
    """A :class:`BatchSpec` from a decoded spec (module doc); ValueError naming the field."""
    if not isinstance(doc, dict):
        raise ValueError("spec: expected a JSON object")
    unknown = set(doc) - {"command", "records", "algorithms", "seeds", "seed_rule", "folds",
                          "model", "options", "sections"}
    if unknown:
        raise ValueError(f"spec: unknown field(s) {', '.join(sorted(unknown))}")
    command = doc.get("command")
    if command not in COMMANDS:
        raise ValueError(f"spec.command: must be one of {', '.join(COMMANDS)}, got {command!r}")
    base = Path(base)
    for name, cmds in (("algorithms", ("identify", "paper")), ("seeds", ("identify", "paper")),
                       ("seed_rule", ("identify", "paper")), ("sections", ("paper",)),
                       ("folds", ("identify", "crossfold")), ("model", ("evaluate",))):
        if name in doc and command not in cmds:
            raise ValueError(f"spec.{name}: not a field of {command} (only of "
                             f"{', '.join(cmds)})")
    options = doc.get("options", {})
    if not isinstance(options, dict):
        raise ValueError("spec.options: expected a JSON object")
    allowed = (set(RESIDUAL_OPTIONS) if command == "residual" else
               set(PAPER_OPTIONS) if command == "paper" else
               {k for k, (d, cmds) in OPTIONS.items() if command in cmds})
    for k in options:
        if k not in allowed:
            raise ValueError(f"spec.options.{k}: not an option of {command}")
    seeds = _int(doc, "seeds", 1, 1)
    seed_rule = doc.get("seed_rule", "index")
    if seed_rule not in ("index", "derived"):
        raise ValueError(f"spec.seed_rule: must be 'index' or 'derived', got {seed_rule!r}")
    sections = []
    if command == "paper":
        if "records" in doc:
            raise ValueError("spec.records: paper simulates its flights (options.flight_seed); "
                             "it reads no records")
        algorithms = _list(doc, "algorithms", PAPER_ALGORITHMS, ALGORITHMS)
        sections = _list(doc, "sections", SECTIONS if options.get("narx", 1) is not None
                         else ("static", "hybrid"), SECTIONS)
        sections = [s for s in SECTIONS if s in sections]      # cdam paper's order
        opts = _paper_options(options, sections)
        records = [f"simulated:flight_seed={opts['flight_seed']}"]
        return BatchSpec(command, records, algorithms, seeds, seed_rule, [None], None, opts,
                         dict(doc), sections)
    records = _records(doc, base)
    algorithms = _list(doc, "algorithms", ["iboa"], ALGORITHMS)
    if command == "crossfold":
        folds = _list(doc, "folds", CROSSFOLD_TYPES, CROSSFOLD_TYPES)
    elif command == "identify":
        folds = list(range(_int(doc, "folds", 1, 1)))
    else:
        folds = [None]
    model = doc.get("model")
    if command == "evaluate":
        if not isinstance(model, str):
            raise ValueError("spec.model: evaluate needs the model file")
        model = os.path.abspath(model if Path(model).is_absolute() else base / model)
        if not Path(model).is_file():
            raise ValueError(f"spec.model: no such file {model!r}")
    if command == "residual":
        return BatchSpec(command, records, algorithms, 1, seed_rule, folds, None,
                         _residual_options(options), dict(doc))
    opts = {k: options.get(k, d) for k, (d, cmds) in OPTIONS.items() if command in cmds}
    if command == "identify":
        opts["folds"] = len(folds)
        split = opts["split"]
        if isinstance(split, bool) or not isinstance(split, (int, float)) or not 0 < split < 1:
            raise ValueError(f"spec.options.split: must be in (0, 1), got {split!r}")
    h = opts.get("horizon")
    if h is not None and (isinstance(h, bool) or not isinstance(h, int) or h < 1):
        raise ValueError(f"spec.options.horizon: must be an integer >= 1, got {h!r}")
    return BatchSpec(command, records, list(algorithms), seeds, seed_rule, folds, model, opts,
                     dict(doc))
