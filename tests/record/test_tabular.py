"""Records as Parquet and pandas DataFrames, other tools' CSVs, the column map and the
missing-value policy (record.dataset, record.columns, record.parquet)."""
import json

import numpy as np
import pandas as pd
import pytest

from cdam_core.record.dataset import Dataset, read_dataset, sidecar_path, write_dataset


def _ds(n=40, seed=0):
    rng = np.random.default_rng(seed)
    return Dataset(t=np.arange(n) * 0.01, columns=["m1", "m2", "x", "vx"],
                   data=rng.standard_normal((n, 4)) * 1e3,
                   meta={"source": "unit test", "inputs": ["m1", "m2"], "outputs": ["x", "vx"]})


def test_parquet_round_trip_exact_with_sidecar(tmp_path):
    ds = _ds()
    p = tmp_path / "r.parquet"
    write_dataset(p, ds)
    back = read_dataset(p)
    assert np.array_equal(back.t, ds.t) and np.array_equal(back.data, ds.data)
    assert back.columns == ds.columns and back.inputs == ["m1", "m2"]
    assert json.loads(sidecar_path(p).read_text())["source"] == "unit test"
    # the file itself is plain Parquet any tool reads
    df = pd.read_parquet(p)
    assert list(df.columns) == ["t", "m1", "m2", "x", "vx"]
    assert np.array_equal(df["vx"].to_numpy(), ds.column("vx"))


def test_dataframe_round_trip_and_flags(tmp_path):
    ds = _ds()
    df = ds.to_dataframe()
    assert list(df.columns) == ["t"] + ds.columns and df.attrs["source"] == "unit test"
    back = Dataset.from_dataframe(df, inputs="m1,m2", outputs=["x"])
    assert np.array_equal(back.data, ds.data) and back.outputs == ["x"]
    # booleans become 0/1, the time column may be the index or PlotJuggler's __time
    df2 = pd.DataFrame({"__time": [0.0, 0.1, 0.2], "flying": [False, True, True], "a": [1, 2, 3]})
    d2 = Dataset.from_dataframe(df2.set_index("__time"))
    assert np.array_equal(d2.t, [0.0, 0.1, 0.2])
    assert np.array_equal(d2.column("flying"), [0.0, 1.0, 1.0])


def test_pandas_and_plotjuggler_csv(tmp_path):
    ds = _ds(10)
    p = tmp_path / "pd.csv"
    ds.to_dataframe().to_csv(p)             # pandas' default: an unnamed index column first
    back = read_dataset(p)
    assert back.columns == ds.columns and np.array_equal(back.data, ds.data)
    q = tmp_path / "pj.csv"
    q.write_text("__time,/imu/x,/imu/y\n1700000000.0,1,2\n1700000000.01,3,4\n")
    pj = read_dataset(q)
    assert pj.columns == ["/imu/x", "/imu/y"] and pj.t[1] == 1700000000.01


def test_missing_values_error_or_split(tmp_path):
    t = np.arange(10) * 0.1
    df = pd.DataFrame({"t": t, "u": np.r_[1.0, 2, np.nan, 4, 5, 6, 7, 8, np.nan, 10],
                       "y": np.arange(10.0), "junk": np.nan})
    with pytest.raises(ValueError, match=r"dataframe: row 2: column 'u': NaN or Inf"):
        Dataset.from_dataframe(df.drop(columns="junk"))
    p = tmp_path / "nan.csv"
    df.drop(columns="junk").to_csv(p, index=False)   # NaN written as empty cells
    with pytest.raises(ValueError, match=r"line 4: column 'u': non-numeric cell ''"):
        read_dataset(p)
    df.to_csv(p, index=False)
    ds = read_dataset(p, inputs="u", outputs="y", nan="split")
    # rows 2 and 8 dropped, the record cut there; the all-NaN column left out
    assert np.array_equal(ds.t, t[[0, 1, 3, 4, 5, 6, 7, 9]])
    assert ds.segments == [(0, 2), (2, 7), (7, 8)]
    assert ds.meta["dropped_rows"] == 2 and ds.meta["dropped_columns"] == ["junk"]
    # the segments survive a round trip through both formats
    for name in ("s.csv", "s.parquet"):
        write_dataset(tmp_path / name, ds)
        assert read_dataset(tmp_path / name).segments == ds.segments
    with pytest.raises(ValueError, match="nan: expected one of"):
        read_dataset(p, nan="drop")


def test_column_map_text_json_and_factor(tmp_path):
    ds = _ds(20)
    p = tmp_path / "r.parquet"
    write_dataset(p, ds)
    m = read_dataset(p, inputs="u1,u2", outputs="x", mapping="u1=m1,u2=m2*0.5")
    assert m.inputs == ["u1", "u2"] and "m1" not in m.columns and "vx" in m.columns
    assert np.array_equal(m.column("u1"), ds.column("m1"))
    assert np.allclose(m.column("u2"), 0.5 * ds.column("m2"), rtol=0, atol=0)
    f = tmp_path / "map.json"
    f.write_text(json.dumps({"u1": "m1", "pos": "x"}))
    j = read_dataset(p, inputs="u1", outputs="pos", mapping=str(f))
    assert np.array_equal(j.column("pos"), ds.column("x"))
    assert Dataset.from_dataframe(ds.to_dataframe(), mapping={"a": "x"}).columns[0] == "a"


@pytest.mark.parametrize("spec, words", [
    ("u1=nope", "map: column 'nope' (for u1) not in the record"),
    ("u1", "expected name=column"),
    ("u1=m1*abc", "factor 'abc' is not a number"),
    ("u1=m1*0", "non-zero"),
    ("u1=m1,u1=m2", "mapped twice"),
    ("=m1", "empty name"),
])
def test_column_map_errors(tmp_path, spec, words):
    p = tmp_path / "r.csv"
    write_dataset(p, _ds(10))
    with pytest.raises(ValueError) as exc:
        read_dataset(p, mapping=spec)
    assert words in str(exc.value)


def test_parquet_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.parquet"
    bad.write_bytes(b"PAR1 this is not a parquet file PAR1")
    with pytest.raises(ValueError, match=r"bad\.parquet: corrupt or unreadable Parquet"):
        read_dataset(bad)
    good = tmp_path / "g.parquet"
    write_dataset(good, _ds(10))
    trunc = tmp_path / "trunc.parquet"
    trunc.write_bytes(good.read_bytes()[:-40])
    with pytest.raises(ValueError, match="corrupt or unreadable Parquet"):
        read_dataset(trunc)
    un = tmp_path / "unsorted.parquet"
    pd.DataFrame({"t": [0.0, 0.2, 0.1], "a": [1.0, 2, 3]}).to_parquet(un)
    with pytest.raises(ValueError, match=r"unsorted\.parquet: row 2: t not strictly increasing"):
        read_dataset(un)
    nt = tmp_path / "notime.parquet"
    pd.DataFrame({"time": [0.0, 0.1], "a": [1.0, 2]}).to_parquet(nt)
    with pytest.raises(ValueError, match="no time column 't'"):
        read_dataset(nt)
    txt = tmp_path / "txt.parquet"
    pd.DataFrame({"t": [0.0, 0.1], "mode": ["a", "b"], "a": [1.0, 2]}).to_parquet(txt)
    assert read_dataset(txt).meta["dropped_columns"] == ["mode"]
    with pytest.raises(ValueError, match="column 'mode' is not numeric"):
        Dataset.from_dataframe(pd.read_parquet(txt))
    with pytest.raises(ValueError, match=r"expected a \.csv or \.parquet"):
        write_dataset(tmp_path / "x.txt", _ds(5))


def test_failed_parquet_write_keeps_old_file(tmp_path, monkeypatch):
    p = tmp_path / "r.parquet"
    write_dataset(p, _ds(10), sidecar=False)
    before = p.read_bytes()
    import cdam_core.base.jsonio as jio

    def boom(*a, **k):
        raise OSError("disk full")
    monkeypatch.setattr(jio.os, "replace", boom)
    with pytest.raises(OSError):
        write_dataset(p, _ds(30, seed=3), sidecar=False)
    assert p.read_bytes() == before
    assert [f.name for f in tmp_path.iterdir() if f.name != "r.parquet"] == []
