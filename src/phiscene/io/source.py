"""What the real-data source classes of a suite (``config.yaml`` ``suites.<suite>.source``) have in common."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from phiscene.params import Params


@dataclass(frozen=True)
class SourceParams(Params):
    """A suite's source: the folder its data lie in and the source's kind.

    Subclasses (:class:`~phiscene.io.rest3d.Rest3dSource`, :class:`~phiscene.io.sam3d.Sam3dSource`,
    :class:`~phiscene.io.placed_suite.PlacedSource`) set :attr:`KIND`, give ``kind`` that default and add their
    import settings.

    Attributes
    ----------
    root
        The data folder, relative to the working directory.
    kind
        The source kind (:data:`phiscene.config.SOURCE_PARAMS`), :attr:`KIND`.
    """

    #: The kind this class reads.
    KIND: ClassVar[str] = ""

    root: str
    kind: str = ""

    def check(self) -> None:
        """Reject another kind (``ValueError``)."""
        if self.kind != self.KIND:
            raise ValueError(f"{self._label} kind must be {self.KIND!r}, got {self.kind!r}")
