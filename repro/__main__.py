"""``python -m repro``: the same command line as the ``repro`` console script."""

from repro.cli import main

raise SystemExit(main())
