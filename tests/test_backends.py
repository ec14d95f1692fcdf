"""The frame loop's edges behind their declared interfaces (rank/backends.py): every exchange
backend and every projection has the protocol's methods with the protocol's parameters."""

import inspect

import pytest

from multigpu.rank.backends import Exchange, Projection
from multigpu.rank.composite import Messages
from multigpu.rank.projection import EachRank, SharedProjection
from multigpu.rank.shared import SharedPieces


def _methods(protocol) -> dict[str, list[str]]:
    return {name: list(inspect.signature(fn).parameters) for name, fn in vars(protocol).items()
            if inspect.isfunction(fn) and not name.startswith("_")}


@pytest.mark.parametrize("protocol, cls", [(Exchange, Messages), (Exchange, SharedPieces),
                                           (Projection, EachRank), (Projection, SharedProjection)])
def test_backend_satisfies_its_protocol(protocol, cls):
    want = _methods(protocol)
    assert want, protocol
    for name, params in want.items():
        assert list(inspect.signature(getattr(cls, name)).parameters) == params, f"{cls.__name__}.{name}"


def test_each_rank_projects_in_the_project_phase():
    from multigpu.rank.timer import Timer

    class Planner:
        def frame(self, camera, f=0):
            return ("view", "proj", "light", camera)

    t = Timer()
    assert EachRank(Planner()).project(0, "rects", t) == ("view", "proj", "light", "rects")
    assert isinstance(EachRank(Planner()), Projection)
    assert set(t.wall) == {"project"}
