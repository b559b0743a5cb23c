"""``python -m semwm.cli ...`` is ``semwm ...``."""

from semwm.cli import main

raise SystemExit(main())
