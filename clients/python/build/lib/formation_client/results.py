"""A run directory's outputs as plain Python structures: `trajectory.csv` (columns in
docs/formats.md) and `summary.json`. Nothing beyond the standard library; `Trajectory.to_pandas()`
uses pandas if it is installed (`pip install ./clients/python[pandas]`).

    import formation_client as fc
    tr = fc.load_trajectory("out/paper-proposed")
    tr.columns                      # ['step', 't', 'agent', 'px', ...]
    a2 = tr.agent(2)                # {'t': [...], 'px': [...], ...} of agent 2 (1-based)
    s = fc.load_summary("out/paper-proposed")
    s["agents"][0]["rms_formation_error_m"]
"""

import csv
import json
import math
from pathlib import Path

#: Columns that hold whole numbers.
INTEGER_COLUMNS = ("step", "agent")


def _path(dir_or_file, name):
    p = Path(dir_or_file)
    return p / name if p.is_dir() else p


def _number(column, text):
    if column in INTEGER_COLUMNS:
        return int(text)
    if text == "NaN":
        return math.nan
    return float(text)  # also "inf", "-inf"


class Trajectory:
    """The rows of `trajectory.csv`: `columns` (names in file order) and `rows` (one list of
    numbers per row, in file order: step by step, agents 1..N within a step)."""

    def __init__(self, columns, rows):
        self.columns = columns
        self.rows = rows
        self._index = {c: i for i, c in enumerate(columns)}

    def __len__(self):
        return len(self.rows)

    def column(self, name):
        """Every value of column `name`, in file order."""
        i = self._index[name]
        return [r[i] for r in self.rows]

    def agents(self):
        """The agent ids (1-based) in the file."""
        return sorted({r[self._index["agent"]] for r in self.rows})

    def agent(self, agent):
        """Agent `agent`'s rows as a dict column -> list of values."""
        a = self._index["agent"]
        mine = [r for r in self.rows if r[a] == agent]
        return {c: [r[i] for r in mine] for c, i in self._index.items()}

    def records(self):
        """Every row as a dict column -> value."""
        return [dict(zip(self.columns, r)) for r in self.rows]

    def to_pandas(self):
        """A pandas DataFrame of the rows (needs pandas)."""
        try:
            import pandas as pd
        except ImportError as e:
            raise ImportError("to_pandas() needs pandas: pip install pandas") from e
        return pd.DataFrame(self.rows, columns=self.columns)


def load_trajectory(dir_or_file):
    """Reads `trajectory.csv` of a run directory (or the file itself)."""
    with open(_path(dir_or_file, "trajectory.csv"), newline="") as f:
        reader = csv.reader(f)
        columns = next(reader)
        rows = [[_number(c, v) for c, v in zip(columns, line)] for line in reader if line]
    return Trajectory(columns, rows)


def load_summary(dir_or_file):
    """Reads `summary.json` of a run directory (or the file itself) as a dict."""
    with open(_path(dir_or_file, "summary.json")) as f:
        return json.load(f)
