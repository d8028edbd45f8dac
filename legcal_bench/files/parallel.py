"""Map a function over jobs on local worker processes with a progress bar, results in
job order (the reports' and suites' many independent session sets)."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor


def map_with_progress(fn, jobs: list, workers: int = 2, desc: str = "", progress: bool = True) -> list:
    """[fn(job) for job in jobs] on `workers` processes (1: in this process); `fn` must
    be picklable (a module-level function)."""
    from tqdm import tqdm

    out = []
    bar = tqdm(total=len(jobs), desc=desc, unit="set", disable=not progress)
    if workers <= 1:
        for j in jobs:
            out.append(fn(j))
            bar.update(1)
    else:
        with ProcessPoolExecutor(workers) as ex:
            for r in ex.map(fn, jobs):
                out.append(r)
                bar.update(1)
    bar.close()
    return out
