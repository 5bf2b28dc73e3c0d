from tetvr.apps.cli import main

raise SystemExit(main())
