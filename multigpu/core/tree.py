"""The GPU tree of Dong & Peng (Sec. 4): how a ``rows x cols`` wall is split, level by level.

Ranks are labelled column-major (``label = col * rows + row``, row 0 at the TOP, col 0 at the
LEFT). A node holding more than one column splits vertically, the low-x (left) child taking the
first ``cols // 2`` columns; a node holding one column splits horizontally, the low-y (bottom)
child taking the bottom ``rows // 2`` rows. Because row 0 is the top row, the bottom rows have the
HIGH row indices. Pure Python, no numpy, MPI or GL: the tree is tiny (K - 1 internal nodes).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from functools import cached_property

VERTICAL = "vertical"  # a left/right line: splits the x axis
HORIZONTAL = "horizontal"  # a bottom/top line: splits the y axis


@dataclass(frozen=True)
class ParInfo:
    """One partitioning operation a rank takes part in (the paper's ParInfo_i).

    ``side`` is where the rank's child lies relative to its sibling: "left"/"right" for a
    vertical split, "bottom"/"top" for a horizontal one (the paper's RS_i).
    """

    method: str
    nc_l: int
    nc_r: int
    side: str
    node: int


@dataclass
class Node:
    """A set of tiles: rows ``r0..r1-1`` (top-down indices) and columns ``c0..c1-1``."""

    id: int
    r0: int
    r1: int
    c0: int
    c1: int
    depth: int
    method: str | None = None  # None for a leaf
    low: "Node | None" = None  # left or bottom child
    high: "Node | None" = None  # right or top child
    label: int | None = None  # the rank, for a leaf

    @property
    def nrows(self) -> int:
        return self.r1 - self.r0

    @property
    def ncols(self) -> int:
        return self.c1 - self.c0

    @property
    def count(self) -> int:
        return self.nrows * self.ncols

    @property
    def is_leaf(self) -> bool:
        return self.method is None


@dataclass
class GpuTree:
    """The binary GPU tree over a ``rows x cols`` grid.

    ``internal`` lists the split nodes in breadth-first order (parents before children), the
    order in which the balancer processes them; ``parinfo[label]`` is each rank's root-to-leaf
    list of ParInfo (its length is the rank's depth).
    """

    rows: int
    cols: int
    root: Node = field(init=False)
    internal: list[Node] = field(init=False)
    leaves: list[Node] = field(init=False)

    def __post_init__(self) -> None:
        if not (isinstance(self.rows, int) and isinstance(self.cols, int)):
            raise ValueError(f"grid must be two integers, got {self.rows!r} x {self.cols!r}")
        if self.rows < 1 or self.cols < 1:
            raise ValueError(f"grid must have at least 1 row and 1 column, got {self.rows}x{self.cols}")
        counter = iter(range(2 * self.rows * self.cols))
        self.root = self._build(0, self.rows, 0, self.cols, 0, counter)
        self.internal, self.leaves = [], []
        queue = [self.root]
        while queue:  # breadth first
            node = queue.pop(0)
            if node.is_leaf:
                self.leaves.append(node)
            else:
                self.internal.append(node)
                queue += [node.low, node.high]
        self.leaves.sort(key=lambda n: n.label)

    def _build(self, r0: int, r1: int, c0: int, c1: int, depth: int, counter) -> Node:
        node = Node(next(counter), r0, r1, c0, c1, depth)
        if node.ncols > 1:
            node.method = VERTICAL
            mid = c0 + node.ncols // 2
            node.low = self._build(r0, r1, c0, mid, depth + 1, counter)
            node.high = self._build(r0, r1, mid, c1, depth + 1, counter)
        elif node.nrows > 1:
            node.method = HORIZONTAL
            # bottom child = the bottom rows // 2 rows = the highest row indices
            mid = r1 - node.nrows // 2
            node.low = self._build(mid, r1, c0, c1, depth + 1, counter)
            node.high = self._build(r0, mid, c0, c1, depth + 1, counter)
        else:
            node.label = c0 * self.rows + r0
        return node

    @property
    def size(self) -> int:
        return self.rows * self.cols

    @cached_property
    def parinfo(self) -> list[list[ParInfo]]:
        out: list[list[ParInfo]] = [[] for _ in range(self.size)]

        def walk(node: Node, path: list[ParInfo]) -> None:
            if node.is_leaf:
                out[node.label] = list(path)
                return
            lo_side, hi_side = ("left", "right") if node.method == VERTICAL else ("bottom", "top")
            for child, side in ((node.low, lo_side), (node.high, hi_side)):
                info = ParInfo(node.method, node.low.count, node.high.count, side, node.id)
                walk(child, path + [info])

        walk(self.root, [])
        return out

    def depth(self, label: int) -> int:
        return len(self.parinfo[label])

    def tile_of(self, label: int) -> tuple[int, int]:
        """(row, col) of a rank's display tile, row 0 at the top."""
        return label % self.rows, label // self.rows

    def describe(self) -> str:
        """The tree as indented text, for reports and `multigpu tree`."""
        lines: list[str] = []

        def walk(node: Node, indent: str) -> None:
            labels = sorted(leaf.label for leaf in _leaves(node))
            if node.is_leaf:
                lines.append(f"{indent}GPU{node.label} tile(row={node.r0}, col={node.c0})")
                return
            ratio = f"{node.low.count}:{node.high.count}"
            lines.append(f"{indent}{{{','.join(map(str, labels))}}} {node.method} split, balRatio {ratio}")
            walk(node.low, indent + "  ")
            walk(node.high, indent + "  ")

        walk(self.root, "")
        return "\n".join(lines)


def _leaves(node: Node) -> list[Node]:
    if node.is_leaf:
        return [node]
    return _leaves(node.low) + _leaves(node.high)


@functools.lru_cache(maxsize=64)
def gpu_tree(rows: int, cols: int) -> GpuTree:
    """The (immutable in use) GPU tree of a wall, built once per shape: the balancer asks for
    it every frame."""
    return GpuTree(rows, cols)
