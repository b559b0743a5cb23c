"""``python -m semwm ...`` is ``semwm ...``."""

from semwm.cli import main

raise SystemExit(main())
