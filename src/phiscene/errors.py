"""Exception types with one-line, user-facing messages."""

from __future__ import annotations

from pathlib import Path


class PhisceneError(Exception):
    """Base class of every error phiscene raises on purpose.

    Attributes
    ----------
    per_scene
        Whether the error is about one scene's data (then a per-scene workflow job records it as a
        failure record and the run goes on, see :mod:`phiscene.failures`) rather than about the setup
        (a missing API key or package, an unreachable service: then the job fails). Subclasses for
        setup problems set it to ``False``.
    """

    per_scene: bool = True


class InputError(PhisceneError, ValueError):
    """Bad user input: names the file and the field that is wrong.

    Parameters
    ----------
    path
        The offending file (or ``None`` when there is no file).
    field
        Dotted path of the offending field, e.g. ``objects[2].pose``.
    problem
        What is wrong, in one line.
    """

    def __init__(self, path: str | Path | None, field: str | None, problem: str):
        self.path = None if path is None else str(path)
        self.field = field
        self.problem = problem
        where = self.path or "<input>"
        if field:
            where += f": {field}"
        super().__init__(f"{where}: {problem}")
