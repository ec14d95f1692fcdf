"""GPU tree shapes, ParInfo, tiles and the Alg. 3 transfer plan."""

import numpy as np
import pytest

from multigpu.core.balance import partition
from multigpu.core.regions import tile_regions
from multigpu.core.tree import GpuTree
from multigpu.core.work import from_partition, transfers

SHAPES = [(1, 1), (1, 2), (2, 1), (2, 2), (1, 3), (3, 1), (1, 5), (5, 1), (1, 7), (7, 1), (2, 3), (3, 2), (4, 4),
          (3, 5)]


@pytest.mark.parametrize("rows,cols", SHAPES)
def test_tree_leaves_are_every_rank_once(rows, cols):
    t = GpuTree(rows, cols)
    assert sorted(leaf.label for leaf in t.leaves) == list(range(rows * cols))
    assert len(t.internal) == rows * cols - 1
    for label in range(rows * cols):
        row, col = t.tile_of(label)
        assert label == col * rows + row
        info = t.parinfo[label]
        assert t.depth(label) == len(info)
        # vertical splits come first, then horizontal ones (columns before rows)
        methods = [i.method for i in info]
        assert methods == sorted(methods, key=lambda m: m != "vertical")
        for i in info:
            assert i.nc_l >= 1 and i.nc_r >= 1
            assert i.side in (("left", "right") if i.method == "vertical" else ("bottom", "top"))


def test_paper_figure2_gpu4_parinfo():
    t = GpuTree(2, 3)
    first = t.parinfo[4][0]
    assert (first.method, first.nc_l, first.nc_r, first.side) == ("vertical", 2, 4, "right")
    assert t.depth(4) == 3
    # GPU4 is column 2, row 0 (top): last split is horizontal and it lies on top
    assert t.parinfo[4][-1].side == "top"


def test_bad_grid():
    with pytest.raises(ValueError):
        GpuTree(0, 3)


def test_tile_regions_follow_convention():
    tiles = tile_regions(2, 2, 10, 20)
    # label 0 = row 0 (top), col 0 -> top-left tile, y from the bottom
    assert tiles[0].tolist() == [0, 20, 10, 40]
    assert tiles[1].tolist() == [0, 0, 10, 20]
    assert tiles[2].tolist() == [10, 20, 20, 40]


def test_tiles_leaves_match_tree():
    # a no-balance "partition" of an empty scene equals the tiles: the tree's pixel
    # orientation (bottom child = bottom rows) agrees with tile_regions
    for rows, cols in SHAPES:
        p = partition(np.zeros((0, 4)), np.zeros(0, np.int64), (rows, cols), (8 * cols, 6 * rows))
        assert (p.regions == tile_regions(rows, cols, 8, 6)).all()


@pytest.mark.parametrize("rows,cols", [(2, 2), (1, 3), (2, 3), (4, 4)])
def test_transfers_cover_every_tile_exactly_once(rows, cols):
    rng = np.random.default_rng(rows * 10 + cols)
    c = rng.normal(0.3, 0.1, (4000, 2))
    rects = np.concatenate([c, c + 0.01], 1)
    W, H = 40 * cols, 30 * rows
    p = partition(rects, rng.integers(1, 100, 4000), (rows, cols), (W, H), strips=W)
    tiles = tile_regions(rows, cols, 40, 30)
    plan = transfers(from_partition(p, np.ones(4000, dtype=np.int64)), tiles)
    got = np.zeros((rows * cols, H, W), dtype=np.int32)
    for t in plan:
        x0, y0, x1, y1 = t.rect
        assert t.pixels > 0
        # the rect lies in the sender's region and in the receiver's tile
        for box in (p.regions[t.sender], tiles[t.receiver]):
            assert box[0] <= x0 and box[1] <= y0 and x1 <= box[2] and y1 <= box[3]
        got[t.receiver, y0:y1, x0:x1] += 1
    for k, (x0, y0, x1, y1) in enumerate(tiles):
        assert (got[k, y0:y1, x0:x1] == 1).all() and got[k].sum() == (x1 - x0) * (y1 - y0)
    assert plan == sorted(plan, key=lambda t: (t.sender, t.receiver, t.index))  # the packing order
