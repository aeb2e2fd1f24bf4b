"""``python -m riderlive``."""

from __future__ import annotations

from riderlive.cli import main

raise SystemExit(main())
