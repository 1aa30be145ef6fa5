"""Tests of repro.runs.report and repro.plots.style on a synthetic results tree."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
from runfiles import complete_run_files

from repro.plots.style import apply_style, save_figure  # noqa: E402
from repro.runs.claims import CLAIMS_COLUMNS, write_claims_csv  # noqa: E402
from repro.runs.report import collect_ours, markdown_table, render_report  # noqa: E402
from repro.runs.trace import TraceRecorder, config_hash  # noqa: E402


@dataclass(frozen=True)
class Cfg:
    gain: float = 2.0


SOURCE_PAPER = '''"""Doc with # ours: not a comment, inside a string."""
K_P = 2.0  # ours: proportional gain, tuned for 1 s settling
TEXT = "# ours: also inside a string"

# ours: 30 cm safety margin
MARGIN_M = 0.3
'''

SOURCE_SHARED = """def clamp(x):
    return min(x, 1.0)  # ours: saturate at 1 rad/s | no source
"""


def _make_tree(root: Path) -> dict[str, Path]:
    results, figures, src = root / "results", root / "figures", root / "src"
    for run, status in (("reach", "completed"), ("avoid", "crashed")):
        rec = TraceRecorder(
            results / "alpha2024" / run, experiment=run, paper="alpha2024", config=Cfg(), seed=1
        )
        for k in range(4):
            rec.record({"t": 0.1 * k, "err_m": 0.01 / (k + 1)})
        rec.close(status=status, reason="RuntimeError: boom" if status == "crashed" else "")
        complete_run_files(results / "alpha2024" / run)
    rows = [
        ("alpha2024", "1", "error converges", "< 5 mm", "3.1 mm", "reproduced"),
        ("alpha2024", "2", "avoids obstacle", "no contact", "run 'avoid' crashed", "not_run"),
        ("alpha2024", "10", "fast", "< 1 ms", "2 ms", "not_reproduced"),
        ("beta2011", "1", "tracks", "< 1 cm", "0.5 cm", "reproduced"),
    ]
    write_claims_csv(pd.DataFrame(rows, columns=list(CLAIMS_COLUMNS[:6])), results / "claims.csv")
    pd.DataFrame(
        [("qp_solve", 1.2e-4, 3.4e-4, 1000, "ci-runner")],
        columns=["benchmark", "median_s", "p95_s", "n", "machine"],
    ).to_csv(results / "bench.csv", index=False)
    apply_style()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    save_figure(fig, figures, "alpha2024", "error_vs_time")
    plt.close(fig)
    (src / "alpha2024").mkdir(parents=True)
    (src / "alpha2024" / "exp.py").write_text(SOURCE_PAPER)
    (src / "lib.py").write_text(SOURCE_SHARED)
    return {"results": results, "figures": figures, "src": src}


def test_collect_ours(tmp_path: Path) -> None:
    tree = _make_tree(tmp_path)
    ours = collect_ours([tree["src"]])
    assert list(ours.columns) == ["file", "line", "code", "why"]
    rows = [(Path(r.file).name, r.line, r.code, r.why) for r in ours.itertuples(index=False)]
    assert rows == [
        ("exp.py", 2, "K_P = 2.0", "proportional gain, tuned for 1 s settling"),
        ("exp.py", 5, "MARGIN_M = 0.3", "30 cm safety margin"),
        ("lib.py", 2, "return min(x, 1.0)", "saturate at 1 rad/s | no source"),
    ]


def test_collect_ours_reads_documentation_comments(tmp_path: Path) -> None:
    """A ``#:`` comment saying ``ours: <why>`` marks the next code line; its why runs on over
    the next ``#:`` lines; a ``#:`` comment without ``ours:`` (or with the word in another
    sense) is no mark, and a ``# ours:`` line right after a doc comment is its own row."""
    (tmp_path / "m.py").write_text(
        "#: Stand height [m]. ours: the camera then sees the part\n"
        "#: from 0.15 m.\n"
        "STAND = 0.20\n"
        "#: Paper value (Sec. 7), not ours, and the hours: fine.\n"
        "FPS = 200\n"
        "#: Gap (ours: a few mm)\n"
        "GAP = 0.005  # ours: the approach stops short\n")
    rows = [(r.line, r.code, r.why) for r in collect_ours([tmp_path]).itertuples(index=False)]
    assert rows == [
        (1, "STAND = 0.20", "the camera then sees the part from 0.15 m."),
        (6, "GAP = 0.005  # ours: the approach stops short", "a few mm)"),
        (7, "GAP = 0.005", "the approach stops short"),
    ]


def test_markdown_table_escapes() -> None:
    table = markdown_table(("a", "b"), [("x|y", "1\n2"), (None, 3)])
    assert table.splitlines() == ["| a | b |", "|---|---|", "| x\\|y | 1<br>2 |", "|  | 3 |"]


def test_render_report(tmp_path: Path) -> None:
    tree = _make_tree(tmp_path)
    out = tmp_path / "REPORT.md"
    now = datetime(2025, 1, 2, 3, 4, 5, tzinfo=UTC)
    assert render_report(tree["results"], tree["figures"], [tree["src"]], out, now=now) == out
    text = out.read_text()

    assert text.index("## Provenance") < text.index("## alpha2024") < text.index("## beta2011")
    assert "2025-01-02T03:04:05" not in text  # the report is a function of the results
    again = tmp_path / "AGAIN.md"
    render_report(tree["results"], tree["figures"], [tree["src"]], again,
                  now=datetime(2031, 5, 6, tzinfo=UTC))
    assert again.read_text() == text
    assert "| numpy |" in text and "| CPU |" in text and "| python |" in text
    alpha = text[text.index("## alpha2024") : text.index("## beta2011")]
    beta = text[text.index("## beta2011") :]

    # claims, with the count and natural order
    assert "**1 of 3 reproduced**" in alpha
    assert alpha.index("| alpha2024 | 2 |") < alpha.index("| alpha2024 | 10 |")
    assert "| alpha2024 | 1 | error converges | < 5 mm | 3.1 mm | reproduced |" in alpha
    assert "**1 of 1 reproduced**" in beta
    # runs
    h = config_hash(Cfg())[:12]
    assert "| avoid | avoid | crashed | RuntimeError: boom | 4 |" in alpha
    assert "| reach | reach | completed |  | 4 |" in alpha
    assert alpha.count(h) == 2
    # figures, linked relative to the report
    assert "![error_vs_time](figures/alpha2024/error_vs_time.png)" in alpha
    assert (tmp_path / "figures/alpha2024/error_vs_time.pdf").is_file()
    # benchmarks
    assert "| benchmark | median_s | p95_s | n | machine |" in text
    assert "| qp_solve | 0.00012 | 0.00034 | 1000 | ci-runner |" in text
    # values chosen by us: per paper, and the shared library
    assert "### Values chosen by us (the papers are silent)" in alpha
    assert "proportional gain, tuned for 1 s settling" in alpha
    assert "`MARGIN_M = 0.3`" in alpha
    assert "src/alpha2024/exp.py" in alpha
    shared = text[text.index("## Values chosen by us (the papers are silent): shared library") :]
    assert "saturate at 1 rad/s \\| no source" in shared
    assert "proportional gain" not in shared
    assert "saturate" not in alpha and "saturate" not in beta.split("## Values chosen")[0]


def test_render_report_without_claims_or_bench(tmp_path: Path) -> None:
    tree = _make_tree(tmp_path)
    (tree["results"] / "claims.csv").unlink()
    out = render_report(tree["results"], tree["figures"], [], tmp_path / "docs" / "REPORT.md")
    assert "\n## Benchmarks\n" in out.read_text()
    # a bench.csv with a paper column goes into that paper's section
    bench = pd.read_csv(tree["results"] / "bench.csv").assign(paper="alpha2024")
    bench.to_csv(tree["results"] / "bench.csv", index=False)
    text = render_report(tree["results"], tree["figures"], [], out).read_text()
    assert "\n## Benchmarks\n" not in text
    assert text.index("### Benchmarks") > text.index("## alpha2024")
    (tree["results"] / "bench.csv").unlink()
    text = render_report(tree["results"], tree["figures"], [], out).read_text()
    assert "claims.csv is missing" in text
    assert "benchmark" not in text
    assert "![error_vs_time](../figures/alpha2024/error_vs_time.png)" in text


def test_save_figure_is_deterministic(tmp_path: Path) -> None:
    apply_style()
    files = []
    for sub in ("a", "b"):
        fig, ax = plt.subplots()
        ax.plot([0, 1, 2], [1, 3, 2], label="x")
        ax.set_xlabel("t (s)")
        files.append(save_figure(fig, tmp_path / sub, "alpha2024", "f"))
        plt.close(fig)
    assert [p.name for p in files[0]] == ["f.png", "f.pdf"]
    for first, second in zip(files[0], files[1], strict=True):
        assert first.read_bytes() == second.read_bytes()
    assert b"CreationDate" not in files[0][1].read_bytes()
    with pytest.raises(ValueError):
        save_figure(fig, tmp_path, "../evil", "f")


def test_variation_note_counts_clauses_and_flips(tmp_path: Path) -> None:
    from repro.runs.claims import VARIATION_COLUMNS, VARIATION_FILE
    from repro.runs.report import _variation_note

    assert "not been measured" in _variation_note(tmp_path, "p2020")
    row = dict.fromkeys(VARIATION_COLUMNS, "")
    pd.DataFrame([{**row, "paper": "p2020", "claim": "1", "clause": "a", "flips": True,
                   "perturbations": "q0:+1e-12 blas:Haswell"},
                  {**row, "paper": "p2020", "claim": "1", "clause": "b", "flips": False,
                   "perturbations": "q0:+1e-12 blas:Haswell"},
                  {**row, "paper": "other", "claim": "1", "clause": "a", "flips": True,
                   "perturbations": "q0:+1e-12"}]).to_csv(tmp_path / VARIATION_FILE,
                                                          index=False)
    note = _variation_note(tmp_path, "p2020")
    assert "2 clauses under 2 perturbations (blas:Haswell, q0:+1e-12" in note
    assert note.endswith("1 flip.")
    assert "not been measured" in _variation_note(tmp_path, "third")
