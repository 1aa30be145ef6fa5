"""Declared trace columns: every column of ``trace.csv`` has a unit and a one-line definition.

A paper declares its columns once (a :class:`Columns`); the episode runner adds its own
(time, joints, commands, ground truth, camera audit). The recorder refuses a trace row with
an undeclared column, and each run writes ``columns.json`` beside ``trace.csv``. Figures and
claims take column names from the same declarations.

Audit-only columns (``audit=True``) hold ground truth that the controller never reads: the
exact projection of a dot, whether it is visible, the true distance to a body.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from repro.errors import ReproError

__all__ = ["Column", "Columns", "COLUMNS_FILE"]

COLUMNS_FILE = "columns.json"
_PLACEHOLDER = re.compile(r"\{i\}")


@dataclass(frozen=True)
class Column:
    """One trace column: its name, unit (``"-"`` for none, ``"bool"``, ``"text"``) and what
    it is."""

    name: str
    unit: str
    definition: str
    audit: bool = False

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "unit": self.unit, "definition": self.definition,
                "audit_only": self.audit}


class Columns:
    """An ordered set of declared columns.

    ``add("q{i}", "rad", "measured position of joint {i}", n=7)`` declares ``q1`` ... ``q7``
    (``{i}`` is 1-based, in the name and in the definition).
    """

    def __init__(self, columns: Iterable[Column] = ()) -> None:
        self._cols: dict[str, Column] = {}
        for c in columns:
            self._put(c)

    def _put(self, col: Column) -> None:
        if not col.name or not col.unit or not col.definition:
            raise ReproError(f"column {col.name!r} needs a name, a unit and a definition")
        old = self._cols.get(col.name)
        if old is not None and old != col:
            raise ReproError(f"column {col.name!r} is declared twice, differently: "
                             f"{old} vs {col}")
        self._cols[col.name] = col

    def add(self, name: str, unit: str, definition: str, *, n: int | None = None,
            audit: bool = False) -> Columns:
        """Declare a column, or ``n`` of them when ``name`` contains ``{i}``; returns self."""
        if _PLACEHOLDER.search(name):
            if n is None:
                raise ReproError(f"column pattern {name!r} needs n")
            for i in range(1, n + 1):
                self._put(Column(name.replace("{i}", str(i)), unit,
                                 definition.replace("{i}", str(i)), audit))
        else:
            self._put(Column(name, unit, definition, audit))
        return self

    def extend(self, other: Columns) -> Columns:
        """Add every column of ``other``; returns self."""
        for c in other:
            self._put(c)
        return self

    def __iter__(self) -> Iterator[Column]:
        return iter(self._cols.values())

    def __contains__(self, name: object) -> bool:
        return name in self._cols

    def __len__(self) -> int:
        return len(self._cols)

    def __getitem__(self, name: str) -> Column:
        return self._cols[name]

    def names(self) -> list[str]:
        return list(self._cols)

    def check(self, names: Iterable[str]) -> None:
        """Raise if a trace column is not declared."""
        missing = [n for n in names if n not in self._cols]
        if missing:
            raise ReproError(f"trace column(s) without a declaration (unit, definition): "
                             f"{', '.join(missing)}")

    def write(self, path: Path, order: Iterable[str]) -> None:
        """Write ``columns.json``: the declarations of the columns in ``order``."""
        order = list(order)
        self.check(order)
        Path(path).write_text(json.dumps({"columns": [self._cols[n].to_json() for n in order]},
                                         indent=1) + "\n", encoding="utf-8")
