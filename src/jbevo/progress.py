"""Progress bars for the slow parts (rendering, loading, training, evaluation): ``tqdm`` on
standard error, shown only where standard error is a terminal (so logs and tests stay clean)."""

from __future__ import annotations

import sys
from collections.abc import Iterable
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")


def progress(items: Iterable[T], desc: str, total: int | None = None) -> Iterable[T]:
    """``items``, with a progress bar labelled ``desc`` while they are consumed."""
    return tqdm(items, desc=desc, total=total, file=sys.stderr, leave=False, disable=None)


__all__ = ["progress"]
