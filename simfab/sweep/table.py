"""The sweep's result table: one row per run, Parquet (pyarrow) and CSV side by side.

Columns: ``run`` (position in the spec's expansion), ``key`` (hash of the run's parameters,
fixed settings, command, base scene and simfab version), the parameters, the collected
figures, the derived columns, ``status`` (see :data:`simfab.sweep.tasks.STATUSES`),
``message`` (one line, empty when ok), ``seconds`` (wall time on the worker) [s], ``worker``
(its address) and ``outputs`` (the run's folder relative to the table, empty when not kept).

Both files are rewritten atomically (temporary name, rename) as results arrive, so an
interrupted sweep leaves a complete table of the runs finished so far.
"""

from __future__ import annotations

from pathlib import Path

from simfab.errors import InputError
from simfab.io.atomic import atomic_path

#: Statuses that are a property of the run's parameters: kept on resume. Other failures
#: (an internal error, a dead worker, a worker of another version) are run again.
FINAL = ("ok", "bad_input", "not_converged")


def table_paths(out: Path, name: str) -> dict[str, Path]:
    return {"parquet": out / f"{name}.parquet", "csv": out / f"{name}.csv"}


def read_table(out: Path, name: str):
    """The existing table of a sweep in ``out`` as a DataFrame, or None when there is none."""
    import pandas as pd

    paths = table_paths(out, name)
    if paths["parquet"].is_file():
        try:
            return pd.read_parquet(paths["parquet"], engine="pyarrow")
        except Exception as e:  # a damaged file: fall back to the CSV twin
            if not paths["csv"].is_file():
                raise InputError(f"cannot read the table to resume ({type(e).__name__}); delete it to start over", where=str(paths["parquet"])) from None
    if paths["csv"].is_file():
        try:
            return pd.read_csv(paths["csv"], dtype={"key": str, "message": str, "worker": str, "outputs": str}, keep_default_na=False, na_values=[""])
        except Exception as e:
            raise InputError(f"cannot read the table to resume ({type(e).__name__}); delete it to start over", where=str(paths["csv"])) from None
    return None


def frame(rows: list[dict], columns: list[str]):
    """DataFrame of ``rows`` in ``columns`` order, sorted by run; numeric columns as numbers
    (None -> NaN), text columns as text."""
    import pandas as pd

    df = pd.DataFrame(rows, columns=columns)
    if len(df):
        df = df.sort_values("run", kind="stable").reset_index(drop=True)
    for c in df.columns:
        if df[c].dtype == object:
            vals = [v for v in df[c] if v is not None and v == v]
            if vals and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
                df[c] = pd.to_numeric(df[c])
            elif vals and all(isinstance(v, bool) for v in vals):
                df[c] = df[c].astype("boolean")
            elif vals:
                df[c] = df[c].map(lambda v: None if v is None or v != v else str(v)).astype("string")
    return df


def write_table(df, out: Path, name: str) -> dict[str, str]:
    """Atomically write ``df`` as NAME.parquet and NAME.csv in ``out``; returns their paths."""
    import pyarrow as pa
    import pyarrow.parquet as pq


    paths = table_paths(out, name)
    with atomic_path(paths["parquet"]) as tmp:
        pq.write_table(pa.Table.from_pandas(df, preserve_index=False), tmp)
    with atomic_path(paths["csv"]) as tmp:
        df.to_csv(tmp, index=False, float_format="%.10g")
    return {k: str(v) for k, v in paths.items()}
