import os

import pytest


def pytest_configure(config):
    os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def shared_data():
    from cdam_core.record.realdata import shared_data_dir

    d = shared_data_dir()
    if not d.is_dir():
        pytest.fail(f"shared data folder not found at {d} (set CDAM_SHARED_DATA)")
    return d


@pytest.fixture(scope="session")
def bundled_record():
    """``bundled_record("emps/DATA_EMPS.mat")``: the path of a record the repository ships under
    data/; fails (never skips) when it is missing: a plain clone has it."""
    from cdam_core.record.realdata import BUNDLED, real_record

    def get(relpath: str):
        assert relpath in BUNDLED, f"{relpath} is not a record shipped under data/"
        p = real_record(relpath)
        if not p.is_file():
            pytest.fail(f"real record {relpath} missing: expected at {p} (data/README.md)")
        return p
    return get
