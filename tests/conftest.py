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
