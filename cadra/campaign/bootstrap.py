"""A fit's parametric bootstrap on the campaign engine: its refits as Dask tasks
(:func:`bootstrap`), so hundreds of them use every worker (docs/fitting.md, "Bootstrap").

The refits are :func:`cadra.studies.bootstrap.replicate` calls, shipped in batches (a batch
per task keeps Dask's per-task cost small against a refit's ~0.3-3 s); each task runs on one
core (:func:`cadra.cores.limit`), so the fit's own threads give way to the workers. The fit is
scattered to the workers once. Without a scheduler a local cluster of one-thread processes is
started for the call (the campaign's own, :func:`cadra.campaign.cluster.local_client`);
``workers=0`` runs the refits here, one after another.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping

from cadra.fitting.result import FitResult
from cadra.studies.bootstrap import BootstrapResult, replicate, summarize

__all__ = ["bootstrap", "replicate_batch"]

#: replicates per Dask task
BATCH = 4


def replicate_batch(result: FitResult, seeds, noise: str) -> list[dict]:
    """Replicates ``seeds`` of ``result`` in this process, on one core."""
    from cadra import cores

    with cores.limit(1):
        return [replicate(result, int(s), noise) for s in seeds]


def bootstrap(result: FitResult, n: int, *, noise: str = "white", seed: int = 0,
              workers: int | None = None, scheduler: str | None = None, client=None,
              progress: bool = False,
              derived: Mapping[str, Callable] | None = None) -> BootstrapResult:
    """``n`` bootstrap refits of ``result`` (:mod:`cadra.studies.bootstrap`), on Dask: an
    existing ``client``, a ``scheduler`` address, or a local cluster of ``workers``
    processes (default: the cores); ``workers=0``: here, one after another. ``seed``: the
    replicates' seeds are ``seed * 1_000_003 + k``. ``derived``: quantities of the fitted
    model to bootstrap too (:func:`cadra.studies.bootstrap.summarize`)."""
    if n < 2:
        raise ValueError(f"bootstrap: at least 2 refits, got {n}")
    if result.problem is None:
        raise ValueError("bootstrap: the fit carries no forward model: nothing to resample")
    seeds = [seed * 1_000_003 + k for k in range(n)]
    t0 = time.perf_counter()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n, desc="bootstrap", unit="refit")
    rows: list[dict] = []
    try:
        if workers == 0 and client is None and scheduler is None:
            for s in seeds:
                rows += replicate_batch(result, [s], noise)
                if bar is not None:
                    bar.update(1)
        else:
            rows = _on_dask(result, seeds, noise, workers, scheduler, client, bar)
    finally:
        if bar is not None:
            bar.close()
    rows.sort(key=lambda r: r["seed"])
    return summarize(result, rows, noise, time.perf_counter() - t0, derived)


def _on_dask(result, seeds, noise, workers, scheduler, client, bar) -> list[dict]:
    from distributed import as_completed

    from cadra.campaign.cluster import local_client

    own = None
    if client is None:
        client, own = local_client(scheduler, workers)
    try:
        fut_result = client.scatter(result, broadcast=True)
        batches = [seeds[k:k + BATCH] for k in range(0, len(seeds), BATCH)]
        futures = [client.submit(replicate_batch, fut_result, b, noise, pure=False)
                   for b in batches]
        rows: list[dict] = []
        for f in as_completed(futures):
            got = f.result()
            rows += got
            if bar is not None:
                bar.update(len(got))
        return rows
    finally:
        if own is not None:
            client.close()
            own.close()

