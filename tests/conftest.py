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


# The longest test files first (CI: two xdist workers, one file at a time, scripts/test.sh runs
# them in this order with --no-loadscope-reorder): a long file started last leaves the other
# worker idle at the end (session 17: 1273 s of wall time for 2351 worker-seconds; the
# fresh-clone file, 548 worker-seconds, was among the last to start). Longest first: the files
# over 60 worker-seconds in that run, longest first, then the files with a test marked slow,
# then the rest as collected. Only the order changes, never what runs.
_LONGEST_FIRST = ("tests/test_fresh_clone.py", "tests/residual/test_independent_joint.py",
                  "tests/firmware/test_monitor_pil.py", "tests/residual/test_residual_flight.py",
                  "tests/residual/test_rotary_axis.py", "tests/robust/test_cli_errors.py")


def pytest_collection_modifyitems(session, config, items):
    def path(item):
        return item.nodeid.split("::", 1)[0]
    slow = {path(i) for i in items if i.get_closest_marker("slow") is not None}
    rank = {p: k for k, p in enumerate(_LONGEST_FIRST)}
    first_seen = {}
    for k, i in enumerate(items):
        first_seen.setdefault(path(i), k)

    def key(item):
        p = path(item)
        return (rank.get(p, len(rank) + (0 if p in slow else 1)), first_seen[p])
    items[:] = sorted(items, key=key)   # stable: a file's tests keep their order
