"""What a tick process that exits 255 leaves behind (the soak saw one once, its log not kept).

Two ways to exit 255 without a word: ``SystemExit(-1)`` (or a C library's ``exit(-1)``),
and an exec that failed before Python ran (multiprocessing's spawn never reads the
child's error pipe). ``last_words.last_words`` makes the first say how it ended and the second
recognisable by the missing "started" line; ``link.exit_reason`` names both."""

from __future__ import annotations

import multiprocessing as mp
import os
from multiprocessing import spawn

import pytest

from riderlive.realtime.last_words import last_words
from riderlive.realtime.link import exit_reason


def exit_minus_one() -> None:
    import logging

    logging.basicConfig(level=logging.INFO, format="%(levelname)s tick: %(message)s")
    with last_words("tick generation 7"):
        raise SystemExit(-1)


def test_systemexit_minus_one_says_so_with_its_traceback(capfd: pytest.CaptureFixture[str]) -> None:
    process = mp.get_context("spawn").Process(target=exit_minus_one)
    process.start()
    process.join(120.0)
    assert process.exitcode == 255
    err = capfd.readouterr().err
    assert f"tick generation 7 started (pid {process.pid})" in err
    assert f"tick generation 7 (pid {process.pid}) ends by SystemExit(-1)" in err
    assert "Traceback" in err and "raise SystemExit(-1)" in err


def test_an_exec_that_fails_exits_255_without_a_word(capfd: pytest.CaptureFixture[str]) -> None:
    python = spawn.get_executable()
    spawn.set_executable("/nonexistent/python")
    try:
        process = mp.get_context("spawn").Process(target=exit_minus_one)
        process.start()
        process.join(60.0)
    finally:
        spawn.set_executable(python)
    assert process.exitcode == 255
    assert "started" not in capfd.readouterr().err
    assert "exec failed" in exit_reason(255) and exit_reason(255).startswith("exit 255")


def test_a_normal_end_is_not_logged(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level("INFO"), last_words("the spare tick"):
        pass
    assert [r.getMessage() for r in caplog.records] == [f"the spare tick started (pid {os.getpid()})"]
    with caplog.at_level("INFO"), pytest.raises(ValueError), last_words("the spare tick"):
        raise ValueError("boom")
    assert caplog.records[-1].getMessage().endswith("ends by ValueError: boom")
    assert exit_reason(1) == "exit 1" and exit_reason(-9) == "SIGKILL" and exit_reason(None) == "running"
