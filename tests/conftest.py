"""Fixtures shared by several test modules."""

import logging

import pytest


@pytest.fixture
def keep_logging():
    """The CLI and the job wrapper reconfigure the root logger; give pytest its handlers back."""
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    yield
    for h in root.handlers:
        if h not in handlers:
            h.close()
    root.handlers[:] = handlers
    root.setLevel(level)
