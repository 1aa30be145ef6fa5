"""Every claim's quote is the paper's words, in the section it names (issue 38: pomares2011
T1 and 5b had their section labels swapped; thomas2024 7 and pomares2011 4 stopped before
words their clauses rely on).

A quote reads ``Sec. X: "words ... words"`` (several such parts may follow each other; ``...``
elides). Each part's fragments are looked up in the paper's text (shared/papers/), compared
on letters and digits only with LaTeX commands dropped (the texts are PDF conversions with
LaTeX maths; the quotes write ``f*_1py`` for ``$f_{1py}^*$``): every part must have a
fragment found, and every fragment found must lie in the section the part names (or one of
its subsections)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from repro.runs.registry import load_papers

PAPERS = Path(__file__).resolve().parent.parent.parent / "shared" / "papers"
TEXTS = {"thomas2024": "thomas2024_proximity_vision_qp.txt",
         "chan2011": "chan2011_mpc_visual_servoing_dcc.txt",
         "pomares2011": "pomares2011_multisensorial_hybrid.txt"}
#: a fragment shorter than this (letters and digits) matches too easily to place it
MIN_FRAGMENT = 20
LABELLED = re.compile(r'Sec\. ([0-9IVX]+(?:[.-]?[0-9A-H]+)*)\)?([^:"]*): "([^"]*)"')
#: a token written in the quote's own notation (``K_v``, ``dV/dt``, ``|dq_j|``): a break
NOTATION = re.compile(r"\S*[_^/\\*|=<>\[\]{}]\S*")

pytestmark = pytest.mark.skipif(not PAPERS.is_dir(), reason="the papers' texts are not here")


def _normalised(text: str) -> tuple[str, list[int]]:
    """Lower-case letters and digits of ``text`` without LaTeX commands, and each kept
    character's index in ``text``."""
    drop = {m.start() + k for m in re.finditer(r"\\[A-Za-z]+", text)
            for k in range(m.end() - m.start())}
    keep = [(c.lower(), i) for i, c in enumerate(text) if i not in drop and c.isalnum()]
    return "".join(c for c, _ in keep), [i for _, i in keep]


def _sections(text: str) -> list[tuple[int, str]]:
    """(start offset, label) of every heading: ``V-A`` style (roman numeral sections and
    lettered subsections) or ``7.2`` style (numbered Markdown headings)."""
    out: list[tuple[int, str]] = []
    top = ""
    offset = 0
    for line in text.splitlines(keepends=True):
        roman = re.match(r"([IVX]+)\. [A-Z]", line)
        letter = re.match(r"([A-H])\. [A-Z]", line)
        numbered = re.match(r"#+\s*\**\s*(\d+(?:\.\d+)*)\.\s", line)
        if roman:
            top = roman.group(1)
            out.append((offset, top))
        elif letter and top:
            out.append((offset, f"{top}-{letter.group(1)}"))
        elif numbered:
            out.append((offset, numbered.group(1)))
        offset += len(line)
    return out


def _section_at(sections: list[tuple[int, str]], pos: int) -> str:
    label = ""
    for start, name in sections:
        if start > pos:
            break
        label = name
    return label


def _quotes() -> list[tuple[str, str, str]]:
    return [(key, c.claim, c.quote) for key, paper in sorted(load_papers().items())
            if paper.claims is not None for c in paper.claims() if c.quote]


def misplaced(paper: str, quote: str) -> list[str]:
    """What is wrong with ``quote`` against ``paper``'s text: a part with no fragment
    found, or a fragment found outside the section its part names."""
    text = (PAPERS / TEXTS[paper]).read_text(encoding="utf-8")
    flat, where = _normalised(text)
    sections = _sections(text)
    problems = []
    parts = LABELLED.findall(quote)
    if not parts:
        return [f"no 'Sec. X: \"...\"' part in {quote[:60]!r}"]
    for label, where_in, words in parts:
        found = 0
        pieces = [run for elided in re.split(r"\.\.\.|\u2026", words)
                  for run in NOTATION.split(elided)]
        for fragment in pieces:
            key = _normalised(fragment)[0]
            if len(key) < MIN_FRAGMENT:
                continue
            at = flat.find(key)
            if at < 0:
                continue  # notation the comparison cannot bridge
            found += 1
            got = _section_at(sections, where[at])
            # the named section, a subsection of it, or a paragraph of the section found
            # (``V-A5``: the fifth paragraph of V-A, which has no heading of its own)
            if not (got == label or got.startswith((f"{label}-", f"{label}."))
                    or (got and label.startswith(got))):
                problems.append(f"'{fragment.strip()[:50]}' is in Sec. {got}, not Sec. {label}")
        if not found and "eq." not in where_in:  # an equation is quoted in notation
            problems.append(f"Sec. {label}: no fragment of {words[:50]!r} is in the paper")
    return problems


@pytest.mark.parametrize(("paper", "claim", "quote"), _quotes(),
                         ids=[f"{p}-{c}" for p, c, _ in _quotes()])
def test_each_quote_is_the_papers_words_in_the_section_it_names(paper: str, claim: str,
                                                                quote: str) -> None:
    assert misplaced(paper, quote) == []


def test_a_swapped_label_and_made_up_words_are_caught() -> None:
    """The two pomares2011 labels as they were (T1 said Sec. 2, 5b Sec. 1), and words the
    paper does not have."""
    t1 = ('Sec. 2: "the execution of the manipulation tasks is divided into two main phases '
          '(see Table 1)"')
    b5 = ('Sec. 1: "This tactile control guarantees that the fingers apply a minimum contact '
          'force to the object"')
    assert misplaced("pomares2011", t1) == [
        "'the execution of the manipulation tasks is divided' is in Sec. 1, not Sec. 2"]
    assert len(misplaced("pomares2011", b5)) == 1
    assert misplaced("pomares2011", t1.replace("Sec. 2", "Sec. 1")) == []
    made_up = 'Sec. V-C: "the hand never comes closer than two centimetres to any ring"'
    assert "no fragment" in misplaced("thomas2024", made_up)[0]


def test_the_quotes_hold_the_words_their_clauses_rely_on() -> None:
    """Issue 38: thomas2024 7's 'no contact' relies on 'works well'; pomares2011 4's held
    coordinate on 'Only one DOF is required'."""
    quotes = {(p, c): q for p, c, q in _quotes()}
    assert "works well" in quotes[("thomas2024", "7")]
    assert "reach their threshold value" in quotes[("thomas2024", "7")]
    assert "Only one DOF is required" in quotes[("pomares2011", "4")]
