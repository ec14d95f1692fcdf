"""Where built scenes and what is made from models once are kept: ``$MULTIGPU_CACHE``, else
``~/.cache/multigpu`` (a leaf module, so every reader of a model finds it without importing the
scene builder)."""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """The cache's folder (made by whoever writes into it)."""
    return Path(os.environ.get("MULTIGPU_CACHE", Path.home() / ".cache" / "multigpu"))
