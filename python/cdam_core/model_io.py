"""Versioned model files: a fitted BPNetwork (weights, scaling, NARX orders) as checked JSON.

Layout: ``{"format": "cdam-model", "version": 1, "sha256": HEX, "model": {...}}`` where the hash
is over the canonical JSON of ``model`` (sorted keys, no spaces). A truncated, altered or foreign
file is rejected with ValueError. Writing is atomic (temporary file, then rename).
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

FORMAT = "cdam-model"
VERSION = 1

__all__ = ["save_model", "load_model", "model_checksum"]


def _canonical(payload: dict) -> bytes:
    return json.dumps(payload, sort_keys=True, separators=(",", ":")).encode()


def model_checksum(payload: dict) -> str:
    return hashlib.sha256(_canonical(payload)).hexdigest()


def save_model(path, model, *, inputs=None, outputs=None, smoothing_passes=0, meta=None) -> str:
    """Write a fitted BPNetwork to ``path``; returns the checksum."""
    if getattr(model, "theta_", None) is None:
        raise ValueError("model: not fitted")
    inputs = list(inputs) if inputs is not None else [f"u{k}" for k in range(model.n_inputs_)]
    outputs = list(outputs) if outputs is not None else [f"y{k}" for k in range(model.n_outputs_)]
    if len(inputs) != model.n_inputs_ or len(outputs) != model.n_outputs_:
        raise ValueError("inputs, outputs: names do not match the model's channel counts")
    payload = {
        "inputs": inputs,
        "outputs": outputs,
        "hidden": int(model.hidden_),
        "activation": model.activation,
        "narx": list(model.narx) if model.narx is not None else None,
        "theta": [float(v) for v in np.asarray(model.theta_, dtype=np.float64)],
        "x_min": [float(v) for v in model.scaler_x_.data_min_],
        "x_max": [float(v) for v in model.scaler_x_.data_max_],
        "y_min": [float(v) for v in model.scaler_y_.data_min_],
        "y_max": [float(v) for v in model.scaler_y_.data_max_],
        "smoothing_passes": int(smoothing_passes),
        "meta": meta or {},
    }
    digest = model_checksum(payload)
    doc = {"format": FORMAT, "version": VERSION, "sha256": digest, "model": payload}
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent or ".", prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(doc, f, indent=1)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return digest


def read_model_payload(path) -> tuple[dict, str]:
    """The checked ``model`` dictionary and its checksum (used by load_model and the exporter)."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read model file ({exc})") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not a cdam model file (corrupt or truncated JSON: {exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ValueError(f"{path}: not a cdam model file (format field missing or wrong)")
    if doc.get("version") != VERSION:
        raise ValueError(f"{path}: model file version {doc.get('version')!r} is not supported (need {VERSION})")
    payload = doc.get("model")
    if not isinstance(payload, dict):
        raise ValueError(f"{path}: model section missing")
    digest = model_checksum(payload)
    if digest != doc.get("sha256"):
        raise ValueError(f"{path}: checksum mismatch: the model file was altered or damaged")
    return payload, digest


def load_model(path):
    """Read a model file written by save_model; returns a fitted ``cdam_core.BPNetwork``."""
    from cdam_core.network import BPNetwork
    from cdam_core.preprocess import MinMaxScaler

    p, _ = read_model_payload(path)
    try:
        i, m, h = len(p["inputs"]), len(p["outputs"]), int(p["hidden"])
        narx = tuple(p["narx"]) if p["narx"] is not None else None
        net = BPNetwork(hidden=h, activation=p["activation"], narx=narx)
        n_in = i if narx is None else narx[0] * m + narx[1] * i
        theta = np.asarray(p["theta"], dtype=np.float64)
        if theta.shape != (n_in * h + h + h * m + m,):
            raise ValueError("theta has the wrong length for the stated sizes")
        sx, sy = MinMaxScaler(), MinMaxScaler()
        sx.data_min_, sx.data_max_ = np.asarray(p["x_min"], float), np.asarray(p["x_max"], float)
        sy.data_min_, sy.data_max_ = np.asarray(p["y_min"], float), np.asarray(p["y_max"], float)
        if sx.data_min_.shape != (i,) or sy.data_min_.shape != (m,):
            raise ValueError("scaling constants do not match the channel counts")
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{path}: model section incomplete ({exc})") from None
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    net.hidden_, net.theta_, net.n_inputs_, net.n_outputs_ = h, theta, i, m
    net.scaler_x_, net.scaler_y_ = sx, sy
    net.input_names_, net.output_names_ = list(p["inputs"]), list(p["outputs"])
    net.smoothing_passes_ = int(p.get("smoothing_passes", 0))
    net.meta_ = p.get("meta", {})
    net.history_ = None
    return net
