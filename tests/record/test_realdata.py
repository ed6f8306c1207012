"""The real records shipped under data/ (issue 22 item 3): each beside its licence and
provenance, its bytes those the provenance lists, and found there before the shared folder."""
import hashlib
import re
from pathlib import Path

import pytest

from cdam_core.record import realdata
from cdam_core.record.realdata import BUNDLED, real_record

DATA = Path(__file__).resolve().parents[2] / "data"


@pytest.mark.parametrize("rel", BUNDLED)
def test_bundled_record_has_licence_provenance_and_listed_checksum(rel):
    p = DATA / rel
    assert p.is_file(), f"{rel} missing from data/"
    assert "Apache License" in (p.parent / "LICENSE").read_text()[:200]
    prov = (p.parent / "PROVENANCE.md").read_text()
    row = re.search(rf"^\| {re.escape(p.name)} \| (\d+) \| ([0-9a-f]{{64}}) \|$", prov, re.M)
    assert row, f"{p.name} not listed in PROVENANCE.md"
    data = p.read_bytes()
    assert len(data) == int(row.group(1))
    assert hashlib.sha256(data).hexdigest() == row.group(2)


def test_data_folder_first_then_shared(tmp_path, monkeypatch):
    shared = tmp_path / "shared"
    (shared / "emps").mkdir(parents=True)
    (shared / "emps" / "DATA_EMPS.mat").write_bytes(b"x")
    (shared / "other").mkdir()
    (shared / "other" / "r.csv").write_text("t\n0\n")
    monkeypatch.setenv("CDAM_SHARED_DATA", str(shared))
    assert real_record("emps/DATA_EMPS.mat") == DATA / "emps" / "DATA_EMPS.mat"
    assert real_record("other/r.csv") == shared / "other" / "r.csv"
    with pytest.raises(ValueError, match="relpath"):
        real_record("../etc/passwd")


def test_missing_bundled_record_is_named_where_it_belongs(tmp_path, monkeypatch):
    monkeypatch.setenv("CDAM_SHARED_DATA", str(tmp_path))
    monkeypatch.setattr(realdata, "repo_data_dir", lambda: tmp_path / "data")
    assert real_record("emps/DATA_EMPS.mat") == tmp_path / "data" / "emps" / "DATA_EMPS.mat"
    assert real_record("nanodrone/x.parquet") == tmp_path / "nanodrone" / "x.parquet"
