"""How much faster two processes are than one on this machine, for the campaign's own heavy
task (a shot flown, rendered and measured: stage one from a specification, M2-2429): the
ceiling of any two-worker speed-up here, Dask or not. Last printed line: a JSON object.

Each process warms up (imports, numba's cache) with one task, then runs ``--tasks`` tasks;
first one process alone, then two at once. ``ceiling_2_processes`` = 2 x (seconds a task
alone) / (seconds a task with both processes busy).

Usage: python tools/bench_two_cores.py [--tasks 3]   (about 3 min; an idle machine)
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import statistics
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "sample_shots" / "specs" / "m2_2429.toml"


def _task() -> None:
    import cadra

    cadra.measure(cadra.simulate(SPEC), workers=1)


def _worker(n: int, start, out) -> None:
    import time

    one_thread()
    _task()                                  # warm-up: imports, numba's cache
    start.wait()
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        _task()
        times.append(time.perf_counter() - t0)
    out.put(times)


def _run(processes: int, n: int) -> list[float]:
    ctx = mp.get_context("spawn")
    start, out = ctx.Barrier(processes), ctx.Queue()
    procs = [ctx.Process(target=_worker, args=(n, start, out)) for _ in range(processes)]
    for p in procs:
        p.start()
    times = [t for _ in procs for t in out.get()]
    for p in procs:
        p.join()
    return times


def run(args) -> dict:
    alone = _run(1, args.tasks)
    pair = _run(2, args.tasks)
    a, b = statistics.median(alone), statistics.median(pair)
    return {"task_seconds_alone": round(a, 2), "task_seconds_two_at_once": round(b, 2),
            "ceiling_2_processes": round(2 * a / b, 3), "tasks_per_process": args.tasks}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tasks", type=int, default=3)
    args = ap.parse_args(argv)
    run_tool("bench_two_cores", ROOT, lambda: run(args), argv=argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
