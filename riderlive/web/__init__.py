"""The browser previs page: static files served at ``/`` by the live service.

``STATIC_DIR`` holds the built page (``index.html``, ``app.js``, ``style.css``) and
``skeletons.json`` (:func:`riderlive.skeleton.hello_skeletons`, written by
``web/build.sh``). Its sources live in the repository's ``web/`` directory.
"""

from __future__ import annotations

from pathlib import Path

STATIC_DIR = Path(__file__).resolve().parent / "static"
MAX_BUNDLE_BYTES = 1_500_000
"""The served page (everything under STATIC_DIR) stays at most this size."""

CHROMIUM = "/usr/bin/chromium"
"""Debian's Chromium, which the browser tests and the page benchmark drive (never a downloaded one)."""
CHROMIUM_ARGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
)
"""Headless, and quiet on a machine with no network beyond the package registries."""


def static_size() -> int:
    """Total bytes of the served files."""
    return sum(p.stat().st_size for p in STATIC_DIR.rglob("*") if p.is_file())
