"""`cdam identify A B C`: several training records (CSV and Parquet, a column map), kept apart."""
import json

import numpy as np

from cdam_core.cli.main import main
from cdam_core.record.dataset import Dataset, write_dataset

FAST = ["--algo", "bp", "--seeds", "1", "--epochs", "2", "--hidden", "2", "--quiet"]


def _rec(path, n, seed, names=("u", "y")):
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, n)
    write_dataset(path, Dataset(t=np.arange(n) * 0.01, columns=list(names),
                                data=np.column_stack([u, np.tanh(2 * u)])))


def test_several_training_records(tmp_path, capsys):
    _rec(tmp_path / "a.csv", 120, 0)
    _rec(tmp_path / "b.parquet", 100, 1, names=("cmd", "out"))
    _rec(tmp_path / "c.csv", 80, 2)
    # b's own names reach the model through the map (the other records have the model's)
    _rec(tmp_path / "b2.parquet", 100, 1)
    argv = ["identify", str(tmp_path / "a.csv"), str(tmp_path / "b2.parquet"), "--test",
            str(tmp_path / "c.csv"), "--inputs", "u", "--outputs", "y", *FAST]
    assert main(argv + ["--json", str(tmp_path / "r.json")]) == 0
    js = json.loads((tmp_path / "r.json").read_text())
    assert js["train_file"] == [str(tmp_path / "a.csv"), str(tmp_path / "b2.parquet")]
    assert main(["identify", str(tmp_path / "b.parquet"), "--test", str(tmp_path / "c.csv"),
                 "--map", "u=cmd,y=out", "--inputs", "u", "--outputs", "y", *FAST]) == 2
    assert "c.csv: map: column 'cmd'" in capsys.readouterr().err   # the map applies to all
    # a NARX network trains across the records (no regressor crossing a seam); a hybrid
    # network would join them: refused, naming why
    assert main(argv + ["--narx", "1,1,1"]) == 0
    capsys.readouterr()
    assert main(argv + ["--narx", "1,1,1", "--model", "hybrid"]) == 2
    assert "a hybrid network trains on one contiguous record" in capsys.readouterr().err
    assert main(argv[:3] + ["--inputs", "u", "--outputs", "y", *FAST]) == 2
    assert "--split: needs one contiguous TRAIN record" in capsys.readouterr().err
