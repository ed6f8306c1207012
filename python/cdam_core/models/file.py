"""The versioned model file: every model kind saved, checked and loaded the same way.

Layout (JSON; schema: ``model-file.schema.json`` beside this module, documented in
docs/MODEL_FILE.md)::

    {"format": "cdam-model", "version": 2, "kind": "bp_network" | "arx" | "hybrid" | "greybox"
                                          | "quad_physics" | "quad_hybrid" | "arx_kstep"
                                          | "arx_direct" | "kstep_blend",
     "inputs": [names], "outputs": [names], "preprocessing": {"smoothing_passes": int},
     "meta": {...free JSON...}, "model": {...the kind's section...},
     "monitor": {...optional: the residual monitor's statistics and thresholds...},
     "checksum": {"sha256": HEX}}

The sha256 is over the canonical JSON (sorted keys, no spaces) of everything but the checksum.
It detects corruption (a truncated or damaged file), not tampering: anyone can recompute it.
Nothing from a file is executed or pasted into code; names must match ``NAME_PATTERN``;
numbers are checked finite and sized against the stated shapes. Version-1 files (a BP network,
the first release's layout) are read as ``bp_network``. Writing is atomic.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

from cdam_core.base.jsonio import plain, write_text_atomic
from cdam_core.models.arx import ArxModel
from cdam_core.models.arx_direct import ArxDirect
from cdam_core.models.arx_kstep import ArxKStep
from cdam_core.models.flight.hybrid import QuadHybrid
from cdam_core.models.flight.physics import QuadPhysics
from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.models.hybrid import HybridNarx
from cdam_core.models.kstep_blend import KStepBlend
from cdam_core.models.network import BPNetwork
from cdam_core.models.protocol import Model
from cdam_core.models.schema import validate_document

FORMAT = "cdam-model"
VERSION = 2
KINDS: dict[str, type] = {"bp_network": BPNetwork, "arx": ArxModel, "hybrid": HybridNarx,
                          "greybox": GreyBox, "quad_physics": QuadPhysics,
                          "quad_hybrid": QuadHybrid, "arx_kstep": ArxKStep,
                          "arx_direct": ArxDirect, "kstep_blend": KStepBlend}
KStepBlend.component_kinds = KINDS       # the blend's components: any kind the file knows
MAX_FILE_BYTES = 256 * 1024 * 1024

__all__ = ["save_model", "load_model", "read_model_file", "ModelFile", "FORMAT", "VERSION",
           "KINDS", "register_kind"]


def register_kind(cls) -> type:
    """Add a model kind (a :class:`Model` subclass with a unique ``kind``) to the file format."""
    if not (isinstance(cls, type) and issubclass(cls, Model) and cls.kind):
        raise ValueError("cls: expected a Model subclass with a kind")
    KINDS[cls.kind] = cls
    return cls


@dataclass
class ModelFile:
    """A loaded model file: the model and the file's other fields."""

    model: Model
    kind: str
    inputs: list[str]
    outputs: list[str]
    smoothing_passes: int = 0
    meta: dict = field(default_factory=dict)
    sha256: str = ""
    monitor: dict | None = None     # the residual monitor's section (evaluate.monitor), if any


def _canonical(doc: dict) -> bytes:
    body = {k: v for k, v in doc.items() if k != "checksum"}
    return json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def save_model(path, model: Model, *, inputs=None, outputs=None, smoothing_passes: int = 0,
               meta=None, monitor=None) -> str:
    """Write a fitted model of any registered kind to ``path``; returns the sha256.
    ``monitor``: the residual monitor's section (``evaluate.monitor.calibrate``), optional."""
    if not isinstance(model, Model) or type(model).kind not in KINDS:
        raise ValueError(f"model: {type(model).__name__} is not a model kind the file knows "
                         f"({', '.join(KINDS)})")
    if not model.is_fitted():
        raise ValueError("model: not fitted")
    n_in, n_out = model.n_inputs_, model.n_outputs_
    inputs = list(inputs) if inputs is not None else [f"u{k}" for k in range(n_in)]
    outputs = list(outputs) if outputs is not None else [f"y{k}" for k in range(n_out)]
    if len(inputs) != n_in or len(outputs) != n_out:
        raise ValueError(f"inputs, outputs: {len(inputs)} and {len(outputs)} names for a model "
                         f"with {n_in} inputs and {n_out} outputs")
    doc = {"format": FORMAT, "version": VERSION, "kind": type(model).kind,
           "inputs": inputs, "outputs": outputs,
           "preprocessing": {"smoothing_passes": int(smoothing_passes)},
           "meta": plain(meta or {}), "model": plain(model.to_dict())}
    if monitor is not None:
        doc["monitor"] = plain(monitor)
    validate_document(doc)                 # what we write, we can read
    _check_monitor(doc, n_out)
    digest = hashlib.sha256(_canonical(doc)).hexdigest()
    doc["checksum"] = {"sha256": digest}
    write_text_atomic(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return digest


def _upgrade_v1(doc: dict) -> dict:
    """A version-1 document (BP network) in the version-2 layout (checksum checked first)."""
    p = doc.get("model")
    if not isinstance(p, dict):
        raise ValueError("model: missing or not an object")
    if hashlib.sha256(json.dumps(p, sort_keys=True, separators=(",", ":")).encode()).hexdigest() \
            != doc.get("sha256"):
        raise ValueError("sha256: checksum mismatch: the model file was altered or damaged")
    try:
        inputs, outputs = list(p["inputs"]), list(p["outputs"])
        section = {k: p[k] for k in ("hidden", "activation", "narx", "theta", "x_min", "x_max",
                                     "y_min", "y_max")}
    except (KeyError, TypeError) as exc:
        raise ValueError(f"model.{exc.args[0] if exc.args else '?'}: missing") from None
    section.update(n_inputs=len(inputs), n_outputs=len(outputs))
    return {"format": FORMAT, "version": VERSION, "kind": "bp_network", "inputs": inputs,
            "outputs": outputs,
            "preprocessing": {"smoothing_passes": p.get("smoothing_passes", 0)},
            "meta": p.get("meta") or {}, "model": section}


def _check_monitor(doc: dict, n_outputs: int) -> None:
    """The monitor section's per-output lists hold one value per output."""
    mon = doc.get("monitor")
    if mon is None:
        return
    for name in ("mean", "std", "h", "ewma_limit", "ar_order") + \
            (("watched",) if "watched" in mon else ()):
        if len(mon[name]) != n_outputs:
            raise ValueError(f"monitor.{name}: {len(mon[name])} values for {n_outputs} outputs")


def _reject_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def read_model_file(path) -> ModelFile:
    """Read, check and load a model file of any kind; ValueError naming the file and field."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_FILE_BYTES:
            raise ValueError(f"{path}: larger than {MAX_FILE_BYTES} bytes; not a model file")
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read model file ({exc})") from None
    try:
        doc = json.loads(text, parse_constant=_reject_constant)
    except (json.JSONDecodeError, ValueError) as exc:
        raise ValueError(f"{path}: not a cdam model file (corrupt or truncated JSON: {exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ValueError(f"{path}: format: not a cdam model file (format field missing or wrong)")
    try:
        version = doc.get("version")
        if version == 1:                   # its own checksum is checked by the upgrade
            digest = str(doc.get("sha256", ""))
            doc = _upgrade_v1(doc)
        elif version != VERSION:
            raise ValueError(f"version: {version!r} is not supported (need {VERSION} or 1)")
        validate_document(doc)
        if version == VERSION:
            if "checksum" not in doc:
                raise ValueError("checksum: missing")
            digest = hashlib.sha256(_canonical(doc)).hexdigest()
            if digest != doc["checksum"]["sha256"]:
                raise ValueError("checksum.sha256: mismatch: the model file was altered or damaged")
        cls = KINDS[doc["kind"]]
        section = doc["model"]
        try:
            model = cls.from_dict(section)
        except KeyError as exc:
            raise ValueError(f"model.{exc.args[0]}: missing") from None
        except TypeError as exc:
            raise ValueError(f"model: wrong type ({exc})") from None
        _check_monitor(doc, model.n_outputs_)
        if len(doc["inputs"]) != model.n_inputs_ or len(doc["outputs"]) != model.n_outputs_:
            raise ValueError(f"inputs, outputs: {len(doc['inputs'])} and {len(doc['outputs'])} "
                             f"names for a model with {model.n_inputs_} inputs and "
                             f"{model.n_outputs_} outputs")
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    return ModelFile(model=model, kind=doc["kind"], inputs=list(doc["inputs"]),
                     outputs=list(doc["outputs"]),
                     smoothing_passes=int(doc["preprocessing"]["smoothing_passes"]),
                     meta=doc["meta"], sha256=digest, monitor=doc.get("monitor"))


def load_model(path) -> Model:
    """The fitted model in a model file (any kind); names and meta on ``input_names_`` etc."""
    mf = read_model_file(path)
    m = mf.model
    m.input_names_, m.output_names_ = mf.inputs, mf.outputs
    m.smoothing_passes_, m.meta_ = mf.smoothing_passes, mf.meta
    return m
