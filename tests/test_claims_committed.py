"""The committed results/claims.csv is what the committed traces give.

Re-evaluates every registered paper's claims from the traces under results/ exactly as
``repro figures`` does (repro/cli.py ``_cmd_figures``: evaluate_claims, then
write_claims_csv) and compares every cell with the committed file. A changed check, claim
text or trace without a regenerated claims.csv fails here; so does a hand-edited table.

Compared exactly, as measured: the checks read the same committed files on every machine,
and their figures (numpy reductions, printed to 2-4 significant digits) came out byte for
byte identical under the default OpenBLAS kernels and five forced families (SkylakeX,
Haswell, Sandybridge, Nehalem, Prescott) on 2026-12-02; a one-digit change of any figure
fails.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from repro.runs import registry
from repro.runs.claims import CLAIMS_COLUMNS, evaluate_claims, read_claims_csv, write_claims_csv

RESULTS = Path(__file__).resolve().parent.parent / "results"


@pytest.fixture(scope="module")
def tables(tmp_path_factory: pytest.TempPathFactory) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(re-evaluated, committed) claims tables, both read back from CSV."""
    committed_path = RESULTS / "claims.csv"
    if not committed_path.is_file():
        pytest.fail(f"{committed_path} is not committed; run `repro figures`")
    papers = registry.load_papers()
    claims = [c for p in papers.values() if p.claims is not None for c in p.claims()]
    assert claims, "no registered paper has claims"
    fresh_path = tmp_path_factory.mktemp("claims") / "claims.csv"
    write_claims_csv(evaluate_claims(claims, RESULTS), fresh_path)
    return read_claims_csv(fresh_path), read_claims_csv(committed_path)


def test_same_claims(tables: tuple[pd.DataFrame, pd.DataFrame]) -> None:
    fresh, committed = tables
    keys = list(zip(fresh["paper"], fresh["claim"], strict=True))
    assert keys == list(zip(committed["paper"], committed["claim"], strict=True)), (
        "results/claims.csv lists other claims than the registered papers; "
        "run `repro figures`")


@pytest.mark.parametrize("column", [c for c in CLAIMS_COLUMNS if c not in ("paper", "claim")])
def test_same_cells(tables: tuple[pd.DataFrame, pd.DataFrame], column: str) -> None:
    fresh, committed = tables
    merged = fresh.merge(committed, on=["paper", "claim"], suffixes=("_fresh", "_committed"))
    differ = merged[merged[f"{column}_fresh"] != merged[f"{column}_committed"]]
    lines = [f"{r.paper} claim {r.claim}:\n  committed: {getattr(r, column + '_committed')}\n"
             f"  from the traces: {getattr(r, column + '_fresh')}"
             for r in differ.itertuples(index=False)]
    assert not lines, (f"results/claims.csv's {column!r} differs from the traces' (run "
                       "`repro figures`):\n" + "\n".join(lines))
