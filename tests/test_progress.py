"""Progress bars that stay readable where standard error is not a terminal (a log file, a pipe, CI)."""

import io
import sys

from roshan.io import LOG_INTERVAL_S, progress_bar


def test_a_bar_in_a_pipe_writes_whole_lines_not_one_growing_line(monkeypatch):
    log = io.StringIO()  # not a terminal
    monkeypatch.setattr(sys, "stderr", log)
    bar = progress_bar(total=1000, desc="eval", unit="episode", mininterval=0.1)
    assert bar.mininterval == LOG_INTERVAL_S  # a line per refresh would flood the log
    for _ in range(1000):
        bar.update(1)
    bar.close()
    text = log.getvalue()
    assert "\r" not in text and "\x1b" not in text
    lines = text.splitlines()
    assert 2 <= len(lines) <= 4, lines  # the start, perhaps one refresh, the end
    assert lines[0].startswith("eval:") and "1000/1000" in lines[-1]
    assert all(len(line) <= 100 for line in lines)


def test_a_disabled_bar_writes_nothing(monkeypatch):
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    bar = progress_bar(total=5, disable=True)
    bar.update(5)
    bar.close()
    assert log.getvalue() == ""
