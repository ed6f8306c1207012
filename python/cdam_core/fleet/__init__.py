"""Fleet scale (issue [fleet]): one command over records x seeds x algorithms x folds, run on
``dask.distributed`` or serially, gathered into one table.

``spec`` reads the batch spec and expands it into tasks (each carrying its own seed),
``tasks`` runs one task on a worker (the worker reads its own record), ``graph`` submits the
tasks to a Dask client (or runs them in order in this process) and writes the table and the
models as the results arrive.
"""
from cdam_core.fleet.spec import BatchSpec, Task, load_spec

__all__ = ["BatchSpec", "Task", "load_spec"]
