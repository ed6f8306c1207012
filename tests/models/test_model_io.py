"""Model files: round trip, and a truncated, altered or foreign file is rejected clearly."""
import json

import numpy as np
import pytest

import cdam_core


@pytest.fixture()
def fitted():
    rng = np.random.default_rng(0)
    U = rng.uniform(-1, 1, (200, 3))
    Y = np.column_stack([U[:, 0] * U[:, 1], np.sin(U[:, 2])])
    return cdam_core.BPNetwork(hidden=4, epochs=5).fit(U, Y), U, Y


def test_round_trip(tmp_path, fitted):
    net, U, _ = fitted
    p = tmp_path / "m.json"
    cdam_core.save_model(p, net, inputs=["a", "b", "c"], outputs=["y1", "y2"])
    back = cdam_core.load_model(p)
    np.testing.assert_array_equal(back.predict(U), net.predict(U))
    assert back.input_names_ == ["a", "b", "c"]


def test_truncated_file_rejected(tmp_path, fitted):
    p = tmp_path / "m.json"
    cdam_core.save_model(p, fitted[0])
    text = p.read_text()
    p.write_text(text[: len(text) // 2])
    with pytest.raises(ValueError, match="corrupt or truncated"):
        cdam_core.load_model(p)


def test_altered_weight_rejected(tmp_path, fitted):
    p = tmp_path / "m.json"
    cdam_core.save_model(p, fitted[0])
    doc = json.loads(p.read_text())
    doc["model"]["theta"][0] += 1e-9
    p.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="checksum"):
        cdam_core.load_model(p)


def test_foreign_and_future_files_rejected(tmp_path, fitted):
    p = tmp_path / "m.json"
    p.write_text(json.dumps({"hello": 1}))
    with pytest.raises(ValueError, match="not a cdam model"):
        cdam_core.load_model(p)
    cdam_core.save_model(p, fitted[0])
    doc = json.loads(p.read_text())
    doc["version"] = 99
    p.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="version"):
        cdam_core.load_model(p)
    p.write_bytes(b"\x00\xff\xfe")
    with pytest.raises(ValueError):
        cdam_core.load_model(p)
