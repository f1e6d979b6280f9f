"""What the real-data source classes of a suite (``config.yaml`` ``suites.<suite>.source``) have in common."""

from __future__ import annotations

from dataclasses import dataclass, fields

from phiscene.params import Params


@dataclass(frozen=True)
class SourceParams(Params):
    """A suite's source: the folder its data lie in and the source's kind.

    Subclasses (:class:`~phiscene.io.rest3d.Rest3dSource`, :class:`~phiscene.io.sam3d.Sam3dSource`,
    :class:`~phiscene.io.placed_suite.PlacedSource`) give ``kind`` their kind as its default (the only kind they
    read) and add their import settings.

    Attributes
    ----------
    root
        The data folder, relative to the working directory.
    kind
        The source kind (:data:`phiscene.config.SOURCE_PARAMS`): the field's default in the subclass.
    """

    root: str
    kind: str = ""

    def check(self) -> None:
        """Reject a kind other than the class's own, the default of its ``kind`` field (``ValueError``)."""
        own = next(f.default for f in fields(self) if f.name == "kind")
        if self.kind != own:
            raise ValueError(f"{self._label} kind must be {own!r}, got {self.kind!r}")
