"""A resource with a ``close()`` is a context manager: ``with Thing(...) as t:`` closes it."""

from __future__ import annotations

import abc
from typing import Self


class Closeable(abc.ABC):
    """Base of the resources closed by ``close()``; ``__exit__`` calls it."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the resource."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
