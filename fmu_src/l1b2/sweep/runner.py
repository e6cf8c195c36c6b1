"""Running a study: samples grouped in chunks, one task per chunk, on the engine of :mod:`l1b2.cluster`.

:func:`execute` yields every finished chunk as a table (the samples with
their outputs) as soon as it is done, so the caller can store it at once
(``l1b2 sweep`` writes ``DIR/chunks/chunk-00012.parquet`` atomically) and
pass the chunks already stored as ``done`` when the same study runs again.
Chunks are cut from the sample table by sample id (``chunk_size`` from the
spec), so they are the same whatever the number of workers; :func:`assemble`
puts them back in sample-id order and checks that no sample is missing or
duplicated.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

import pandas as pd

from ..cluster import run_tasks
from ..errors import SimulationError
from .tasks import TaskContext, output_columns, run_chunk


def chunk_bounds(n_samples: int, chunk_size: int) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` row ranges of the chunks (chunk id = list index)."""
    return [(a, min(a + chunk_size, n_samples)) for a in range(0, n_samples, chunk_size)]


def chunk_frame(samples: pd.DataFrame, rows: list[dict], ctx: TaskContext) -> pd.DataFrame:
    """The samples of a chunk with their outputs, ``status`` and ``error`` columns, typed."""
    res = pd.DataFrame(rows)
    cols = list(output_columns(ctx))
    res = res[["sample_id"] + cols + ["status", "error"]]
    for c in cols:
        res[c] = res[c].astype("boolean") if c == "stalled" else res[c].astype(float)
    res["status"] = res["status"].astype(str)
    res["error"] = res["error"].astype(str)
    out = samples.reset_index(drop=True).merge(res, on="sample_id", how="left", validate="one_to_one")
    if len(out) != len(samples) or out["status"].isna().any():
        raise SimulationError("a chunk came back without a result for every one of its samples")
    return out


def execute(samples: pd.DataFrame, ctx: TaskContext, chunk_size: int, *, done: Iterable[int] = (), client=None,
            traverse: Callable | None = None) -> Iterator[tuple[int, pd.DataFrame]]:
    """Run the chunks not in ``done``; yield ``(chunk_id, table)`` as each finishes.

    ``client``: a Dask client (:func:`l1b2.cluster.dask_client`), or ``None``
    to run in this process. ``traverse(sample, motor, ctx)`` replaces the
    co-simulated traverse (tests); it must be importable on the workers.
    """
    done = set(done)
    bounds = chunk_bounds(len(samples), chunk_size)
    todo = [cid for cid in range(len(bounds)) if cid not in done]
    args = [(cid, samples.iloc[slice(*bounds[cid])].to_dict("records"), ctx, traverse) for cid in todo]
    for _, (cid, rows) in run_tasks(run_chunk, args, client=client, name="l1b2-sweep"):
        yield cid, chunk_frame(samples.iloc[slice(*bounds[cid])], rows, ctx)


def assemble(chunks: Iterable[pd.DataFrame], n_samples: int) -> pd.DataFrame:
    """All chunks as one table in sample-id order; refuses a missing or duplicated sample."""
    df = pd.concat(list(chunks), ignore_index=True).sort_values("sample_id", kind="stable").reset_index(drop=True)
    ids = df["sample_id"].to_numpy()
    if len(df) != n_samples or (ids != range(n_samples)).any():
        dup = df["sample_id"][df["sample_id"].duplicated()].tolist()
        raise SimulationError(f"the chunks hold {len(df)} results for {n_samples} samples"
                              + (f" (duplicated sample ids {dup[:5]})" if dup else ""))
    return df
