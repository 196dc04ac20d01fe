"""The campaign's Dask cluster: a client of a running scheduler, or a local cluster of
one-thread worker processes started for the run (docs/campaign.md, "On Dask"). One home for
how CADRA starts its workers, for campaigns and for a fit's bootstrap."""

from __future__ import annotations

__all__ = ["PRE_SPAWN", "local_client"]

#: Dask's configuration of the environment its nanny gives a worker process at its start
PRE_SPAWN = "distributed.nanny.pre-spawn-environ"


def local_client(scheduler: str | None, workers: int | None):
    """A Dask client of the scheduler at ``scheduler``, or of a new local cluster of
    ``workers`` one-thread processes (default: the cores): ``(client, cluster or None)``;
    the caller closes both."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler, timeout="30s"), None
    import dask

    from cadra import cores

    n = workers or cores.available()
    # Dask's nanny starts each worker with MALLOC_TRIM_THRESHOLD_=65536. Setting that
    # threshold turns off glibc's adaptive mmap threshold, so every large array (an image, a
    # blurred copy) is mapped and unmapped afresh, its pages zeroed each time: stage one ran
    # 27 % slower on a worker than in a plain process (8.0 s against 6.3 s a shot,
    # docs/campaign.md, "On Dask"). The local cluster's workers keep glibc's default; a
    # threshold set in the environment is still inherited.
    from cadra.fitting.sensitivity import METHOD_ENV, process_method

    # the workers' fits use this process's sensitivity method: a replicate or a shot is then
    # the same number here and on a worker, whether or not the tangent code's first compile
    # has finished in between (docs/fitting.md, "Sensitivities")
    with dask.config.set({f"{PRE_SPAWN}.MALLOC_TRIM_THRESHOLD_": None,
                          f"{PRE_SPAWN}.{METHOD_ENV}": process_method()}):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=logging.ERROR)
    return Client(cluster), cluster
