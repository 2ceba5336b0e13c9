"""Progress bars for long stages: shown on a terminal, silent with --quiet or when stderr is not a TTY."""

from __future__ import annotations

import logging
import sys
from contextlib import contextmanager


@contextmanager
def progress(total: int, description: str):
    """A bar with ``update(n)``; a no-op unless stderr is a terminal and INFO messages are shown."""
    enabled = sys.stderr.isatty() and logging.getLogger("fuzzymesh").isEnabledFor(logging.INFO)
    if not enabled:
        yield _Silent()
        return
    from tqdm import tqdm

    with tqdm(total=total, desc=description, unit="step", leave=False, file=sys.stderr) as bar:
        yield bar


class _Silent:
    def update(self, n: int = 1) -> None:
        pass
