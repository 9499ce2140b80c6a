"""White-box tests of the packer's compiled canvas kernels (segparam.canvas) against brute force.

They call the kernels and some of their private helpers directly, so they change with the canvas;
tests/test_pack.py checks the packer through its public functions only.
"""

from __future__ import annotations

import numpy as np
import pytest

from segparam import canvas


def _canvas_with_blobs(width: int, height: int, pad: int, seed: int, rule: str):
    """A canvas (block 1) with six random blobs placed by one rule's search, and its state."""
    rng = np.random.default_rng(seed)
    forbid, sky, coarse, prefix, max_free, bits = canvas.new_canvas(width, height, pad, 1)
    sky_min = np.empty(width, dtype=np.int64)
    canvas._sky_minima(sky, sky_min, 0, width)
    for _ in range(6):
        blob = rng.random((int(rng.integers(3, 12)), int(rng.integers(3, 12)))) < 0.7
        blob |= np.arange(blob.shape[1]) == 0
        r, c = blob.shape
        if rule == "holes":
            runs, cr, cc = canvas.coarse_runs(blob, r, c, 1)
            got, rows, cols = canvas.holes(prefix, max_free, bits, runs, cr, cc, 1)
        else:
            bottom = np.where(blob.any(axis=0), np.argmax(blob, axis=0), canvas._EMPTY)
            got, rows, cols = canvas.resting(
                bottom.astype(np.int64), c, sky, sky_min, height - pad - r, 1, 16
            )
        if got:
            row, col = canvas.slide(forbid, blob, r, c, int(rows[0]), int(cols[0]), 1024)
            canvas.place(forbid, sky, coarse, prefix, max_free, bits, 1, blob, r, c, row, col, pad)
            canvas._sky_minima(sky, sky_min, 0, width)
    return forbid, sky, sky_min, prefix, max_free, bits


def _fits(forbid, mask, row, col) -> bool:
    """Brute force: the footprint lies inside the canvas and meets no forbidden texel."""
    r, c = mask.shape
    if row < 0 or col < 0 or row + r > forbid.shape[0] or col + c > forbid.shape[1]:
        return False
    return not (mask & forbid[row : row + r, col : col + c]).any()


def test_candidates_are_the_lowest_fitting_positions_per_column() -> None:
    # with one texel per coarse cell the hole search must return exactly the lowest fitting
    # row of each column (brute force below), lowest first
    forbid, _, _, prefix, max_free, bits = _canvas_with_blobs(64, 72, 1, 0, "holes")
    fp = np.tri(9, 14, 4, dtype=bool)
    r, c = fp.shape
    lowest = {}
    for col in range(64 - c + 1):
        for row in range(72 - r + 1):
            if _fits(forbid, fp, row, col):
                lowest[col] = row
                break
    runs, cr, cc = canvas.coarse_runs(fp, r, c, 1)
    got, rows, cols = canvas.holes(prefix, max_free, bits, runs, cr, cc, 10**4)
    assert got, "the canvas still has room"
    rows, cols = rows[:got].tolist(), cols[:got].tolist()
    assert rows == sorted(rows) and rows[0] == min(lowest.values())
    assert dict(zip(cols, rows, strict=True)) == lowest


@pytest.mark.parametrize("seed", range(3))
def test_free_run_starts_from_bit_sets_match_brute_force(seed: int) -> None:
    # the hole search finds where a run of free cells fits from 64-cell words, with shifts that
    # cross word boundaries; check it against a direct scan on rows of 300 cells
    rng = np.random.default_rng(seed)
    nc = 300
    free = rng.random((4, nc)) < rng.uniform(0.7, 0.999, (4, 1))
    coarse = ~free
    forbid = coarse.copy()  # one texel per cell
    _, _, c, prefix, max_free, bits = canvas.new_canvas(nc, 4, 0, 1)
    canvas._pool_rows(forbid, 1, c, prefix, max_free, bits, 0, 4, 0, nc)
    out = np.empty(bits.shape[1], dtype=np.uint64)
    for row in range(4):
        for length in (1, 2, 5, 63, 64, 65, 130, 200):
            canvas._runs_of(bits, row, length, out)
            got = [p for p in range(64 * len(out)) if int(out[p // 64]) >> (p % 64) & 1]
            want = [p for p in range(nc - length + 1) if free[row, p : p + length].all()]
            assert got == want


def test_trailing_zeros_is_the_index_of_the_lowest_set_bit() -> None:
    # the hole search reads the set bits of its 64-cell words lowest first with this intrinsic
    from numba import njit

    @njit
    def lowest_bits(words):
        out = np.empty(len(words), dtype=np.int64)
        for i in range(len(words)):
            out[i] = canvas._trailing_zeros(words[i])
        return out

    rng = np.random.default_rng(0)
    words = [1 << k for k in range(64)] + [(1 << 64) - 1, 0b1011000, 1 << 63 | 1 << 5]
    words += rng.integers(1, 2**63, 50, dtype=np.uint64).tolist()
    want = [(w & -w).bit_length() - 1 for w in words]
    assert lowest_bits(np.array(words, dtype=np.uint64)).tolist() == want


def test_coarse_hole_search_never_misses_a_free_coarse_position() -> None:
    # with 3-texel cells a position is reported only where the coarse footprint meets no
    # forbidden cell, and every such position of the lowest row is reported
    forbid = _canvas_with_blobs(96, 108, 1, 3, "holes")[0]
    _, _, coarse, prefix, max_free, bits = canvas.new_canvas(96, 108, 1, 3)
    nr, nc = coarse.shape
    canvas._pool_rows(forbid, 3, coarse, prefix, max_free, bits, 0, nr, 0, nc)
    fp = np.tri(10, 16, 5, dtype=bool)
    runs, cr, cc = canvas.coarse_runs(fp, *fp.shape, 3)
    cfp = np.zeros((cr, cc), dtype=bool)
    for i, c0, c1 in runs:
        cfp[i, c0 : c1 + 1] = True
    free = {
        (y, j)
        for y in range(coarse.shape[0] - cr + 1)
        for j in range(coarse.shape[1] - cc + 1)
        if not (coarse[y : y + cr, j : j + cc] & cfp).any()
    }
    got, rows, cols = canvas.holes(prefix, max_free, bits, runs, cr, cc, 10**4)
    found = set(zip(rows[:got].tolist(), cols[:got].tolist(), strict=True))
    assert found <= free
    lowest = min(y for y, _ in free)
    assert {p for p in free if p[0] == lowest} <= found


# ----------------------------------------------------------------------------------------------
# packing: invariants


def test_resting_positions_are_the_lowest_drop_positions() -> None:
    # a footprint "rests" at (row, col) when it can come straight down from the top to there:
    # it fits at that row and at every row above. The skyline search must return, per column,
    # the lowest such row (brute force below), lowest first.
    forbid, sky, sky_min, _, _, _ = _canvas_with_blobs(64, 72, 1, 1, "rest")
    fp = np.tri(9, 14, 4, dtype=bool)[::-1].copy()
    r, c = fp.shape
    top = 72 - 1 - r  # highest row inside the top border
    lowest = {}
    for col in range(64 - c + 1):
        if not _fits(forbid, fp, top, col):
            continue
        row = top
        while row > 0 and _fits(forbid, fp, row - 1, col):
            row -= 1
        lowest[col] = row
    bottom = np.where(fp.any(axis=0), np.argmax(fp, axis=0), canvas._EMPTY).astype(np.int64)
    got, rows, cols = canvas.resting(bottom, c, sky, sky_min, top, 10**4, 16)
    assert got, "the canvas still has room"
    rows, cols = rows[:got].tolist(), cols[:got].tolist()
    assert rows == sorted(rows) and rows[0] == min(lowest.values())
    assert dict(zip(cols, rows, strict=True)) == lowest


@pytest.mark.parametrize("seed", range(4))
def test_resting_search_pruning_gives_the_full_searchs_answer(seed: int) -> None:
    # the pruned search (sampled columns first, skyline blocks skipped) must return exactly
    # the `count` best of the full max-plus correlation, on rough skylines
    rng = np.random.default_rng(seed)
    width, height, pad = 300, 340, 2
    sky = np.full(width, height, dtype=np.int64)
    sky[2:-2] = np.cumsum(rng.integers(-6, 7, 296)).clip(-40, 200) + 60
    sky_min = np.empty(width, dtype=np.int64)
    canvas._sky_minima(sky, sky_min, 0, width)
    for _ in range(5):
        mask = np.tri(int(rng.integers(5, 60)), int(rng.integers(20, 200)), 0, dtype=bool)
        mask = mask[:, ::-1] if rng.random() < 0.5 else mask
        mask |= rng.random(mask.shape) < 0.3
        rows, cols = mask.shape
        bottom = np.where(mask.any(axis=0), np.argmax(mask, axis=0), canvas._EMPTY)
        full = np.maximum(
            (np.lib.stride_tricks.sliding_window_view(sky, cols) - bottom).max(axis=1), 0
        )
        top = height - pad - rows
        x = np.flatnonzero(full <= top)
        for count in (1, 2, 7):
            best = x[np.lexsort((x, full[x]))[:count]]
            got, r, c = canvas.resting(bottom.astype(np.int64), cols, sky, sky_min, top, count, 16)
            assert list(zip(r[:got].tolist(), c[:got].tolist(), strict=True)) == [
                (int(full[j]), int(j)) for j in best
            ]


def test_turned_footprints_and_their_profiles_match_numpy() -> None:
    # the quarter turns are searched from the base footprint's profiles, never rasterized again
    rng = np.random.default_rng(4)
    for _ in range(10):
        base = rng.random((int(rng.integers(1, 15)), int(rng.integers(1, 15)))) < 0.5
        base[rng.integers(base.shape[0]), rng.integers(base.shape[1])] = True
        r, c = base.shape
        low, high, left, right, cy, cx = canvas._profiles(base, r, c)
        for k in range(4):
            want = np.rot90(base, -k)
            out = np.zeros((max(r, c), max(r, c)), dtype=bool)
            assert canvas.turned(base, r, c, k, out) == want.shape
            assert np.array_equal(out[: want.shape[0], : want.shape[1]], want)
            prof = np.empty(max(r, c), dtype=np.int64)
            rr, cc, y = canvas._turned_bottom(low, high, left, right, r, c, cy, cx, k, prof)
            bottom = np.where(want.any(axis=0), np.argmax(want, axis=0), canvas._EMPTY)
            assert (rr, cc) == want.shape and np.array_equal(prof[:cc], bottom)
            per_row = want.sum(axis=1)
            assert np.isclose(y, per_row @ np.arange(len(per_row)) / per_row.sum())


def _star(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A star-shaped fan of n outer points around the origin, faces counter-clockwise."""
    theta = np.sort(rng.uniform(0, 2 * np.pi, n))
    radius = rng.uniform(0.4, 1.0, n)
    uv = np.vstack([[0.0, 0.0], np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])])
    j = np.arange(n)
    return uv, np.column_stack([np.zeros(n, dtype=np.int64), 1 + j, 1 + (j + 1) % n])


@pytest.mark.parametrize("seed", range(4))
def test_profiles_from_runs_match_the_fill_then_the_profiles(seed: int) -> None:
    # a trial fills a footprint from its outline's runs (_run_profiles of outline_runs); it
    # must give _fill_into's texels and _profiles' numbers
    from segparam import raster

    rng = np.random.default_rng(seed)
    for _ in range(5):
        uv, F = _star(int(rng.integers(5, 40)), rng)
        B = raster.boundary_edges(F)
        P = uv * rng.uniform(1, 20)
        P = P - P.min(axis=0) + rng.uniform(0, 1, 2)
        if rng.random() < 0.5:  # vertices on texel lines, the delicate cases
            P = np.round(P * 2) / 2
        rows, cols = (int(v) for v in np.floor(P.max(axis=0))[::-1] + 2)
        want = raster.fill_outline(P, B, (rows, cols), 1e-4)
        got = np.zeros((rows, cols), dtype=bool)
        ptr, start, end = raster.outline_runs(P, B, 1e-4, rows, cols)
        profiles = canvas._run_profiles(got, ptr, start, end, rows, cols)
        assert np.array_equal(got, want)
        for i in range(rows):  # each row's runs: sorted, with a gap between any two
            a, b = start[ptr[i] : ptr[i + 1]], end[ptr[i] : ptr[i + 1]]
            assert (a <= b).all() and (a[1:] > b[:-1] + 1).all()
        for a, b in zip(profiles, canvas._profiles(want, rows, cols), strict=True):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", range(4))
def test_edges_and_coarse_runs_from_runs_match_every_turned_mask(seed: int) -> None:
    # the trial lists a large footprint's lower and left edges and its coarse runs from its
    # runs, for each quarter turn; they must be the cells _leading_edges finds on the turned
    # mask (in any order) and the runs coarse_runs finds there
    from segparam import raster

    rng = np.random.default_rng(seed)
    for _ in range(5):
        uv, F = _star(int(rng.integers(5, 40)), rng)
        if rng.random() < 0.5:  # a notch: rows and columns of two runs
            F = F[: max(len(F) - int(rng.integers(1, 4)), 1)]
        B = raster.boundary_edges(F)
        P = uv * rng.uniform(2, 30)
        P = P - P.min(axis=0) + rng.uniform(0, 1, 2)
        rows, cols = (int(v) for v in np.floor(P.max(axis=0))[::-1] + 2)
        base = np.zeros((rows, cols), dtype=bool)
        ptr, start, end = raster.outline_runs(P, B, 1e-4, rows, cols)
        canvas._run_profiles(base, ptr, start, end, rows, cols)
        for k in range(4):
            mask = np.ascontiguousarray(np.rot90(base, -k))
            want = canvas._leading_edges(mask, *mask.shape)
            got = canvas._turned_edges(ptr, start, end, rows, cols, k)
            for a, b in zip(got, want, strict=True):
                assert sorted(map(tuple, a.tolist())) == sorted(map(tuple, b.tolist()))
            for block in (1, 3, 4):  # and its coarse footprint, for the "holes" rule
                runs, cr, cc = canvas._turned_coarse_runs(ptr, start, end, rows, cols, k, block)
                want_runs, wr, wc = canvas.coarse_runs(mask, *mask.shape, block)
                assert (cr, cc) == (wr, wc) and np.array_equal(runs, want_runs)


def test_hull_boxes_of_many_charts_match_one_chart_at_a_time_and_brute_force() -> None:
    # the packer measures the minimum-area boxes of all charts over pack._SMALL_HULL points in
    # one padded call
    from segparam import pack
    from segparam.errors import InvalidMeshError

    rng = np.random.default_rng(5)
    sets = [rng.normal(size=(int(n), 2)) * rng.uniform(0.1, 5, 2) for n in rng.integers(13, 60, 9)]
    sets.append(np.array([[0, 0], [3, 0], [3, 1], [0, 1], [1, 0.5]] * 3, dtype=float))  # a box
    angle, fill = pack._hull_boxes(sets, np.arange(len(sets)))

    def box(uv: np.ndarray, t: float) -> float:
        c, s = np.cos(t), np.sin(t)
        return float(np.ptp(uv @ np.array([[c, -s], [s, c]]).T, axis=0).prod())

    for k, uv in enumerate(sets):
        one = pack._hull_boxes([uv])
        assert (angle[k], fill[k]) == (one[0][0], one[1][0])
        least = min(box(uv, t) for t in np.radians(np.arange(0, 180, 0.25)))
        assert box(uv, angle[k]) <= least * (1 + 1e-9)
    assert fill[-1] == pytest.approx(1.0)
    with pytest.raises(InvalidMeshError, match="chart 1: chart uv points span no area"):
        pack._hull_boxes([sets[0], np.array([[0, 0], [1, 1], [2, 2.0]] * 5)], np.arange(2))


def test_hulls_are_qhulls_counter_clockwise_from_the_lowest_leftmost_point() -> None:
    # the packer's batched monotone chain against scipy's qhull, on random sets, a grid (points
    # on the hull's edges, which are not vertices) and sets with repeated points
    from scipy.spatial import ConvexHull

    from segparam import pack

    rng = np.random.default_rng(7)
    sets = [rng.normal(size=(int(n), 2)) for n in rng.integers(3, 80, 20)]
    sets.append(np.stack(np.meshgrid(np.arange(4.0), np.arange(3.0)), -1).reshape(-1, 2))
    sets.append(np.repeat(rng.normal(size=(6, 2)), 3, axis=0))
    sizes = np.array([len(P) for P in sets])
    ptr = np.r_[0, np.cumsum(sizes)]
    S = np.concatenate([P[np.lexsort((P[:, 1], P[:, 0]))] for P in sets])
    index, count = pack._hulls(S, ptr)
    for c, P in enumerate(sets):
        got = S[index[ptr[c] : ptr[c] + count[c]]]
        want = P[ConvexHull(P).vertices]
        assert len(got) == len(want)
        assert {tuple(p) for p in got} == {tuple(p) for p in want}
        assert tuple(got[0]) == min(tuple(p) for p in P)  # lowest x, then lowest y
        a, b = np.roll(got, -1, 0) - got, np.roll(got, -2, 0) - np.roll(got, -1, 0)
        turns = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        assert (turns > 0).all()  # counter-clockwise, strictly convex


def test_stable_order_is_a_stable_argsort():
    """The orientations' scan order (``_stable_order``) is numpy's stable argsort of the first n
    keys, ties in index order."""
    rng = np.random.default_rng(3)
    for n in (0, 1, 2, 7, 40, 96):
        for _ in range(20):
            keys = rng.integers(0, 6, size=100) * 0.5  # many ties
            assert np.array_equal(
                canvas._stable_order(keys, n), np.argsort(keys[:n], kind="mergesort")
            )


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (7, 300), (40, 33)])
def test_leading_edges_are_the_cells_a_move_newly_covers(shape) -> None:
    # brute force: a cell whose neighbour below (left) is outside the footprint, in row-major
    # order; the kernel reads only mask[:rows, :cols] of a larger buffer (as the trial's slots)
    rng = np.random.default_rng(shape[0] * 1000 + shape[1])
    rows, cols = shape
    big = rng.random((rows + 3, cols + 5)) < 0.3
    mask = rng.random(shape) < 0.6
    big[:rows, :cols] = mask
    down, left = canvas._leading_edges(big, rows, cols)
    below = np.vstack([np.zeros((1, cols), bool), mask[:-1]])
    before = np.hstack([np.zeros((rows, 1), bool), mask[:, :-1]])
    assert np.array_equal(down, np.argwhere(mask & ~below))
    assert np.array_equal(left, np.argwhere(mask & ~before))
