"""Progress bars: on a terminal they show, with --quiet or into a pipe they stay silent."""

from __future__ import annotations

import io
import logging
import sys

from engine.progress import progress


class Terminal(io.StringIO):
    def isatty(self):
        return True


def run_bar(monkeypatch, stream, level):
    monkeypatch.setattr(sys, "stderr", stream)
    logging.getLogger("fuzzymesh").setLevel(level)
    try:
        with progress(5, "packing volume") as bar:
            for _ in range(5):
                bar.update()
    finally:
        logging.getLogger("fuzzymesh").setLevel(logging.NOTSET)
    return stream.getvalue()


def test_a_terminal_shows_the_bar(monkeypatch):
    assert "packing volume" in run_bar(monkeypatch, Terminal(), logging.INFO)


def test_quiet_or_a_pipe_shows_nothing(monkeypatch):
    assert run_bar(monkeypatch, Terminal(), logging.WARNING) == ""
    assert run_bar(monkeypatch, io.StringIO(), logging.INFO) == ""
