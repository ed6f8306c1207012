"""The dataset format reader/writer (issue 4, "The dataset format")."""
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdam_core.record.dataset import Dataset, read_dataset, sidecar_path, write_dataset


def _write(tmp_path, text, name="d.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_round_trip_exact_and_sidecar(tmp_path):
    rng = np.random.default_rng(1)
    t = np.arange(50) * 0.01
    cols = ["T", "tau_phi", "phi", "X", "q1", "extra"]
    data = rng.standard_normal((50, 6)) * 1e3
    ds = Dataset(t=t, columns=cols, data=data, meta={"source": "unit test", "model": "m"})
    p = tmp_path / "rec.csv"
    write_dataset(p, ds)
    back = read_dataset(p)
    assert np.array_equal(back.t, t) and np.array_equal(back.data, data)
    assert back.columns == cols
    assert back.inputs == ["T", "tau_phi"] and back.outputs == ["phi", "X", "q1"]
    side = json.loads(sidecar_path(p).read_text())
    assert side["source"] == "unit test" and side["model"] == "m"
    assert side["units"]["T"] == "N" and side["units"]["phi"] == "rad"
    assert side["rate"] == pytest.approx(100.0)
    assert back.rate == pytest.approx(100.0)
    assert np.array_equal(back.column("X"), data[:, 3])
    assert np.array_equal(back.select(["X", "T"]), data[:, [3, 0]])
    assert np.array_equal(back.column("t"), t)


def test_standard_names_without_sidecar_and_explicit_selection(tmp_path):
    p = _write(tmp_path, "t,a,phi,b,T\n0,1,2,3,4\n0.5,5,6,7,8\n")
    ds = read_dataset(p)
    assert ds.meta == {}
    assert ds.inputs == ["T"] and ds.outputs == ["phi"]
    assert ds.rate == pytest.approx(2.0)
    ds = read_dataset(p, inputs="a,b", outputs=["phi"])
    assert ds.inputs == ["a", "b"]
    assert np.array_equal(ds.select(ds.inputs), [[1, 3], [5, 7]])


@pytest.mark.parametrize("text, line, words", [
    ("", 1, "empty file"),
    ("a,b\n1,2\n", 1, "first column must be 't'"),
    ("t,a,a\n0,1,2\n", 1, "duplicate column name 'a'"),
    ("t,a\n0,1\n1,x\n", 3, "non-numeric cell 'x'"),
    ("t,a\n0,1\n1,\n", 3, "non-numeric cell ''"),
    ("t,a\n0,1\n1,nan\n", 3, "NaN or Inf"),
    ("t,a\n0,1\n1,inf\n", 3, "NaN or Inf"),
    ("t,a\n0,1\n1,2,3\n", 3, "expected 2 cells, found 3"),
    ("t,a\n0,1\n1\n", 3, "expected 2 cells, found 1"),
    ("t,a\n0,1\n1,2\n1,3\n", 4, "not strictly increasing"),
    ("t,a\n0,1\n-1,2\n", 3, "not strictly increasing"),
    ("t,a\n", 2, "no data rows"),
    ("t,a\n0,1\n\n1,2\n", 3, "empty line"),
])
def test_errors_name_file_and_line(tmp_path, text, line, words):
    p = _write(tmp_path, text)
    with pytest.raises(ValueError) as exc:
        read_dataset(p)
    msg = str(exc.value)
    assert str(p) in msg and f"line {line}:" in msg and words in msg


def test_unknown_columns_and_missing_file(tmp_path):
    p = _write(tmp_path, "t,a\n0,1\n1,2\n")
    with pytest.raises(ValueError, match="inputs: unknown column 'zz'"):
        read_dataset(p, inputs=["zz"])
    with pytest.raises(ValueError, match="outputs: unknown column 'q9'"):
        read_dataset(p, outputs="q9")
    ds = read_dataset(p)
    with pytest.raises(ValueError, match="unknown column 'b'"):
        ds.column("b")
    with pytest.raises(FileNotFoundError):
        read_dataset(tmp_path / "none.csv")


def test_corrupt_sidecar(tmp_path):
    p = _write(tmp_path, "t,a\n0,1\n1,2\n")
    sidecar_path(p).write_text('{\n  "rate": 1,\n  oops\n}')
    with pytest.raises(ValueError, match=r"d\.json: line 3: corrupt JSON"):
        read_dataset(p)
    sidecar_path(p).write_text("[1, 2]")
    with pytest.raises(ValueError, match="JSON object"):
        read_dataset(p)


def test_sidecar_selection_is_used(tmp_path):
    p = _write(tmp_path, "t,u,y\n0,1,2\n1,2,3\n")
    sidecar_path(p).write_text(json.dumps({"inputs": ["u"], "outputs": ["y"], "rate": 1}))
    ds = read_dataset(p)
    assert ds.inputs == ["u"] and ds.outputs == ["y"] and ds.rate == 1.0


def test_dataset_rejects_bad_arrays():
    with pytest.raises(ValueError, match="t: not strictly increasing"):
        Dataset(t=[0, 0], columns=["a"], data=[[1], [2]])
    with pytest.raises(ValueError, match="data: expected shape"):
        Dataset(t=[0, 1], columns=["a", "b"], data=[[1], [2]])
    with pytest.raises(ValueError, match="data: NaN or Inf at sample 1"):
        Dataset(t=[0, 1], columns=["a"], data=[[1], [np.nan]])
    with pytest.raises(ValueError, match="t: expected a non-empty"):
        Dataset(t=[], columns=["a"], data=np.zeros((0, 1)))
    with pytest.raises(ValueError, match="duplicate"):
        Dataset(t=[0], columns=["a", "a"], data=[[1, 2]])
    with pytest.raises(ValueError, match="comma"):
        Dataset(t=[0], columns=["a,b"], data=[[1]])


def test_atomic_write_leaves_old_file_on_failure(tmp_path, monkeypatch):
    p = tmp_path / "r.csv"
    good = Dataset(t=[0.0, 1.0], columns=["a"], data=[[1.0], [2.0]])
    write_dataset(p, good)
    before = p.read_text()

    import cdam_core.record.dataset as mod

    def boom(*a, **k):
        raise OSError("disk full")
    monkeypatch.setattr(mod.os, "replace", boom)
    with pytest.raises(OSError):
        write_dataset(p, Dataset(t=[0.0, 1.0, 2.0], columns=["a"], data=[[5.0], [6.0], [7.0]]))
    assert p.read_text() == before
    assert [f.name for f in tmp_path.iterdir() if f.name.endswith(".tmp")] == []


def test_round_trip_30000_by_15(tmp_path):
    """A record of a 30 s, 1 kHz flight's size comes back exactly (its reading speed against
    pandas is benchmarks/bench_record.py's)."""
    rng = np.random.default_rng(0)
    n = 30000
    ds = Dataset(t=np.arange(n) * 1e-3, columns=[f"c{i}" for i in range(14)],
                 data=rng.standard_normal((n, 14)))
    p = tmp_path / "big.csv"
    write_dataset(p, ds)
    back = read_dataset(p)
    assert np.array_equal(back.data, ds.data) and np.array_equal(back.t, ds.t)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64),
                min_size=2, max_size=20))
def test_round_trip_any_finite_float(tmp_path_factory, values):
    p = tmp_path_factory.mktemp("h") / "h.csv"
    ds = Dataset(t=np.arange(len(values), dtype=float), columns=["v"], data=np.array(values)[:, None])
    write_dataset(p, ds)
    assert np.array_equal(read_dataset(p).data[:, 0], np.array(values))


def test_written_files_get_the_umask_mode(tmp_path):
    import os
    p = tmp_path / "m.csv"
    write_dataset(p, Dataset(t=[0.0, 1.0], columns=["a"], data=[[1.0], [2.0]]))
    mask = os.umask(0)
    os.umask(mask)
    assert (p.stat().st_mode & 0o777) == (0o666 & ~mask)
    assert (sidecar_path(p).stat().st_mode & 0o777) == (0o666 & ~mask)
