"""The 2-worker LocalCluster the fleet tests share (started once: about 3 s)."""
import pytest


@pytest.fixture(scope="session")
def client():
    pytest.importorskip("dask.distributed")
    from dask.distributed import Client, LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster, Client(cluster) as c:
        yield c
