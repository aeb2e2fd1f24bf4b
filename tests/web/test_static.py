"""The served page as files: size budget, no network beyond the service, current skeletons."""

from __future__ import annotations

import json
import re

from riderlive.skeleton import hello_skeletons
from riderlive.web import MAX_BUNDLE_BYTES, STATIC_DIR, static_size


def test_bundle_fits_the_budget_and_is_complete() -> None:
    for name in ("index.html", "app.js", "style.css", "skeletons.json"):
        assert (STATIC_DIR / name).is_file(), name
    assert 100_000 < static_size() <= MAX_BUNDLE_BYTES


def test_page_loads_nothing_from_elsewhere() -> None:
    html = (STATIC_DIR / "index.html").read_text()
    refs = re.findall(r'(?:src|href)="([^"]+)"', html)
    assert refs, "no references found: the pattern is wrong"
    for ref in refs:
        assert not re.match(r"^(https?:)?//", ref), f"index.html loads {ref} from the network"
    bundle = (STATIC_DIR / "app.js").read_text()
    assert not re.search(r"""import\s*\(?\s*["']https?://""", bundle)


def test_committed_skeletons_are_current() -> None:
    """web/build.sh writes skeletons.json; it must match the Python skeletons."""
    assert json.loads((STATIC_DIR / "skeletons.json").read_text()) == json.loads(json.dumps(hello_skeletons()))
