"""The results table of a sweep: ``results.csv`` as rows arrive, ``results.parquet`` at the end.

A table belongs to one spec. Writing into a table that holds rows needs ``--resume`` (keep the
spec's finished rows, run the rest and retry the ``error`` rows) or ``--overwrite`` (start
again); rows of a table that the spec no longer has are dropped on resume. Floats are written
as the shortest text that reads back to the same number (``repr``). The Parquet file has one
type per column whatever the values (:func:`column_type`), so tables of different sweeps
concatenate.
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from vjm_ros.core.errors import ConfigurationError

if TYPE_CHECKING:
    import pyarrow as pa

RESULTS_CSV = "results.csv"
RESULTS_PARQUET = "results.parquet"
RETRIED = ("error",)
"""Statuses of rows that ``--resume`` runs again (a run that could not happen, not a result)."""
STRING_COLUMNS = ("key", "scene", "integrator", "closure", "kernel", "status", "message")
INTEGER_COLUMNS = ("substeps",)
BOOLEAN_COLUMNS = ("projection", "finite")


def column_type(name: str) -> pa.DataType:
    """The Parquet (Arrow) type of a column: strings, whole numbers, booleans, else float64."""
    import pyarrow as pa

    if name in STRING_COLUMNS:
        return pa.string()
    if name in INTEGER_COLUMNS:
        return pa.int64()
    if name in BOOLEAN_COLUMNS:
        return pa.bool_()
    return pa.float64()


def cell(value: object) -> str:
    """A value as CSV text: floats round-trippable and short, None empty."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, float):  # numpy's float64 too: never its repr "np.float64(...)"
        return float.__repr__(float(value))
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value)


@dataclass
class TableStart:
    """What a table holds before a sweep writes into it.

    Attributes
    ----------
    path : Path
    kept : list of dict
        Rows of the spec finished before (``--resume``); they stay.
    retried : int
        ``error`` rows that run again.
    dropped : int
        Rows of keys the spec does not have (a spec that shrank), removed.
    replaced : int
        Rows of a table started again (``--overwrite``).
    """

    path: Path
    kept: list[dict] = field(default_factory=list)
    retried: int = 0
    dropped: int = 0
    replaced: int = 0

    @property
    def done(self) -> set[str]:
        """Keys of the rows kept."""
        return {row["key"] for row in self.kept}


def inspect_table(out: Path, columns: list[str], keys: set[str], resume: bool,
                  overwrite: bool) -> TableStart:
    """Check what ``out``'s table holds against the spec, without writing anything.

    Raises
    ------
    ConfigurationError
        A table with rows and neither ``resume`` nor ``overwrite``; a table of other columns
        to resume; both flags.
    """
    path = out / RESULTS_CSV
    if resume and overwrite:
        raise ConfigurationError("--resume, --overwrite: expected one of them, found both")
    start = TableStart(path)
    if not path.exists():
        return start
    try:
        with path.open(newline="") as f:
            reader = csv.DictReader(f)
            rows, header = list(reader), reader.fieldnames
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ConfigurationError(f"{path}: expected a results table, found {exc}") from None
    if not rows:
        return start
    if overwrite:
        start.replaced = len(rows)
        return start
    if not resume:
        raise ConfigurationError(
            f"{path}: expected no results table, found one with {len(rows)} rows; "
            "--resume to finish it (the same spec), --overwrite to replace it, or another --out")
    if header != columns:
        raise ConfigurationError(
            f"{path}: expected the columns of this spec to resume, found {header} "
            "(use another --out, or --overwrite)")
    for row in rows:
        if row["key"] not in keys:
            start.dropped += 1
        elif row["status"] in RETRIED or not row["status"]:
            start.retried += 1
        else:
            start.kept.append(row)
    return start


def begin_table(start: TableStart, columns: list[str]) -> None:
    """Write the table's header and the rows it keeps (atomically: a crash leaves either)."""
    start.path.parent.mkdir(parents=True, exist_ok=True)
    tmp = start.path.with_name(start.path.name + ".tmp")
    with tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(start.kept)
    os.replace(tmp, start.path)


def write_parquet(csv_path: Path, parquet_path: Path) -> Path:
    """The CSV table as Parquet, each column of its fixed type (:func:`column_type`)."""
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    with csv_path.open(newline="") as f:
        names = next(csv.reader(f))
    table = pacsv.read_csv(csv_path, convert_options=pacsv.ConvertOptions(
        column_types={n: column_type(n) for n in names}, strings_can_be_null=True,
        true_values=["True"], false_values=["False"]))
    pq.write_table(table, parquet_path)
    return parquet_path
