"""Settings for the whole suite.

Hypothesis's per-example deadline (200 ms by default) measures the host, not the code: on
two shared cores under load an example that takes 5 ms quiet takes 400 ms, and the test
fails for it. Speed is measured in ``bench/``, so the suite's profile has no deadline."""

from __future__ import annotations

from hypothesis import settings

settings.register_profile("riderlive", deadline=None)
settings.load_profile("riderlive")
