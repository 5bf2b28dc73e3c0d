"""``python -m tetvr.apps.cli``: the command line (as ``python -m tetvr`` and ``tetvr``)."""

from tetvr.apps.cli import main

raise SystemExit(main())
