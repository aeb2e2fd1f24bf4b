"""The page's header shows the SMPTE timecode of the frame shown (headless Chromium)."""

from __future__ import annotations

import pytest

from riderlive import timecode as tc
from riderlive.timecode import Rate
from tests.web.conftest import PageUnderTest

pytestmark = pytest.mark.browser


def test_the_header_shows_the_frames_timecode(live_page: PageUnderTest) -> None:
    live_page.wait_for("typeof riderlive.timecode === 'string'", timeout=10)
    text = live_page.page.locator("#timecode").inner_text()
    assert text.startswith("TC ")
    first = tc.parse(text[3:], Rate.FPS_25)  # the service's default rate
    live_page.wait_for(f"riderlive.timecode !== {text[3:]!r}", timeout=5)  # it runs
    later = tc.parse(live_page.page.locator("#timecode").inner_text()[3:], Rate.FPS_25)
    assert 0 < tc.frames_between(later, first, Rate.FPS_25) < 25 * 10
    assert live_page.errors == []
