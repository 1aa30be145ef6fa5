"""Regenerate the short-run reference traces (tests/references.py lists them), then
remeasure their tolerances.

Run after an intended behaviour change, and say in the commit which references moved::

    .venv/bin/python tests/make_reference.py                      # every reference
    .venv/bin/python tests/make_reference.py --only pomares2011/exp3
    .venv/bin/python tests/measure_tolerances.py --only pomares2011/exp3
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from references import REFERENCES, write_reference  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="+", default=sorted(REFERENCES), choices=sorted(REFERENCES),
                    metavar="ID")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        for rid in args.only:
            ref = REFERENCES[rid]
            df = ref.make(Path(d) / rid.replace("/", "__"))
            write_reference(ref, df)
            print(rid, len(df), "rows")
    print("now remeasure their tolerances: .venv/bin/python tests/measure_tolerances.py "
          "--only " + " ".join(args.only))


if __name__ == "__main__":
    main()
