"""Simulated hosts for the tests (``multigpu.studies.simhosts``): a machine that cannot make them
skips the test with the reason (no namespaces here, a tool missing)."""

from __future__ import annotations

import pytest

from multigpu.studies.simhosts import SimHosts as _SimHosts
from multigpu.studies.simhosts import Unavailable


class SimHosts(_SimHosts):
    __doc__ = _SimHosts.__doc__

    def __enter__(self) -> "SimHosts":
        try:
            return super().__enter__()
        except Unavailable as exc:
            pytest.skip(str(exc))
