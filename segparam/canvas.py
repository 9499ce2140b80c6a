"""The raster packer's canvas and its two placement rules, compiled (numba).

`pack.py` tells the story (scale search, chart order, orientations); this module does the texel
work of one trial: it places every chart at one scale, largest first, each where the centroid
of its footprint ends up lowest, and reports the height the layout needs. One compiled call per
trial, so that thousands of small charts cost no Python round trip each.

The canvas is `width` texels wide and `height` tall (taller than the texture during the scale
search, so that an over-full trial still reports how much height it needed):

``forbid[i, j]``
    True where a new footprint texel may not go: the border band (left, right, bottom, top) and
    the placed footprints dilated by the padding.
``sky[j]``
    One more than the highest forbidden texel of column j below the top border (the canvas
    height in the side borders): everything above it is free.
``sky_min``
    The skyline's minimum over the `_SKY_BLOCK` columns from each column on (the resting
    search skips a run of positions at once with it).
``coarse``, ``prefix``, ``max_free``, ``free_bits``
    ``forbid`` pooled into blocks of ``block x block`` texels ("any"), its row-wise prefix
    sums (so that a run of cells is tested in O(1)), each coarse row's longest free run, and its
    free cells as bit sets (64 a word). All of these are derived from ``forbid`` and ``sky`` and
    refreshed where a placement changes them.

Placement rules (``rule``):

``REST`` (0)
    The chart comes straight down onto the skyline in every orientation it has (fine angles
    times quarter turns): at column j it rests at ``max_c (sky[j + c] - bottom[c])``. Each
    angle is rasterized once and its quarter turns are searched from the footprint's profiles.
    The best `n_starts` resting positions over all orientations are slid down and left.
``HOLES`` (1)
    Quarter turns only, but anywhere there is room, also under overhangs and inside other
    charts' concavities: per coarse column the lowest coarse row where the coarse footprint
    meets no forbidden cell; the `n_candidates` lowest of those per orientation are slid.

Conventions: grids are indexed ``[row = v, col = u]``; ``np.rot90(mask, -k)`` turns a
footprint by k counter-clockwise quarter turns of its uv frame (see ``pack._turns``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from segparam.raster import _raster_into, outline_runs

REST = 0
HOLES = 1
# Empty columns of a footprint's lower profile: far below anything.
_EMPTY = 1 << 30
# Columns per block of the skyline's block minima, which let the resting search skip a block of
# positions at once (16: 64 blocks at 1024 texels).
_SKY_BLOCK = 16


@intrinsic
def _trailing_zeros(typingctx, word):  # pragma: no cover - compiled
    """Index of the lowest set bit of a non-zero uint64: one instruction (LLVM's ``cttz``),
    where a loop testing bit after bit took a third of the "holes" rule's time on 2,000
    triangles (``perf`` on the compiled trial)."""
    if word != types.uint64:
        return None

    def codegen(context, builder, signature, args):
        # the flag (an i1 true): a zero word is undefined (the callers never pass one)
        return builder.cttz(args[0], context.get_constant(types.boolean, True))

    return types.int64(types.uint64), codegen


@njit(cache=True, nogil=True)
def _sky_minima(sky, sky_min, c0, c1):  # pragma: no cover - compiled
    """Refresh ``sky_min[x] = min(sky[x : x + _SKY_BLOCK])`` where columns c0 .. c1 - 1 changed."""
    width = len(sky)
    for x in range(max(c0 - _SKY_BLOCK + 1, 0), min(c1, width)):
        m = sky[x]
        for j in range(x + 1, min(x + _SKY_BLOCK, width)):
            m = min(m, sky[j])
        sky_min[x] = m


@njit(cache=True, nogil=True)
def _before(a0, a1, a2, a3, b0, b1, b2, b3):  # pragma: no cover - compiled
    """Lexicographic (a0, a1, a2, a3) < (b0, b1, b2, b3)."""
    if a0 != b0:
        return a0 < b0
    if a1 != b1:
        return a1 < b1
    if a2 != b2:
        return a2 < b2
    return a3 < b3


# ----------------------------------------------------------------------------------------------
# footprints


@njit(cache=True, nogil=True)
def turned(base, rows, cols, k, out):  # pragma: no cover - compiled
    """``np.rot90(base[:rows, :cols], -k)`` written into `out`; returns its shape."""
    if k == 0:
        for i in range(rows):
            for j in range(cols):
                out[i, j] = base[i, j]
        return rows, cols
    if k == 1:
        for i in range(cols):
            for j in range(rows):
                out[i, j] = base[rows - 1 - j, i]
        return cols, rows
    if k == 2:
        for i in range(rows):
            for j in range(cols):
                out[i, j] = base[rows - 1 - i, cols - 1 - j]
        return rows, cols
    for i in range(cols):
        for j in range(rows):
            out[i, j] = base[j, cols - 1 - i]
    return cols, rows


@njit(cache=True, nogil=True)
def _profiles(base, rows, cols):  # pragma: no cover - compiled
    """One pass over a footprint: per column its lowest and highest row, per row its left-most
    and right-most column (`_EMPTY` / -1 where empty), and its centroid (row, col)."""
    low = np.full(cols, _EMPTY, dtype=np.int64)
    high = np.full(cols, -1, dtype=np.int64)
    left = np.full(rows, _EMPTY, dtype=np.int64)
    right = np.full(rows, -1, dtype=np.int64)
    total = 0
    sum_r = 0
    sum_c = 0
    for i in range(rows):
        n = 0
        for j in range(cols):
            if base[i, j]:
                n += 1
                sum_c += j
                if low[j] == _EMPTY:
                    low[j] = i
                high[j] = i
                if left[i] == _EMPTY:
                    left[i] = j
                right[i] = j
        total += n
        sum_r += i * n
    total = max(total, 1)
    return low, high, left, right, sum_r / total, sum_c / total


@njit(cache=True, nogil=True)
def _run_profiles(base, ptr, start, end, rows, cols):  # pragma: no cover - compiled
    """`_profiles` of a footprint given as runs (`raster.outline_runs`), which it writes into
    `base` (zeros): a run at a time, as slice fills (the per-texel pass was half of the "rest"
    rule's time on the bone scan's and the cow's large charts)."""
    low = np.full(cols, _EMPTY, dtype=np.int64)
    high = np.full(cols, -1, dtype=np.int64)
    left = np.full(rows, _EMPTY, dtype=np.int64)
    right = np.full(rows, -1, dtype=np.int64)
    total = 0
    sum_r = 0
    sum_c = 0
    for i in range(rows):
        n = 0
        for r in range(ptr[i], ptr[i + 1]):
            a, b = start[r], end[r]
            base[i, a : b + 1] = True
            high[a : b + 1] = i
            n += b - a + 1
            sum_c += (a + b) * (b - a + 1) // 2
        if ptr[i + 1] > ptr[i]:
            left[i], right[i] = start[ptr[i]], end[ptr[i + 1] - 1]
        total += n
        sum_r += i * n
    for i in range(rows - 1, -1, -1):  # downwards: the lowest row's fill stays
        for r in range(ptr[i], ptr[i + 1]):
            low[start[r] : end[r] + 1] = i
    total = max(total, 1)
    return low, high, left, right, sum_r / total, sum_c / total


@njit(cache=True, nogil=True)
def _turned_bottom(low, high, left, right, rows, cols, cy, cx, k, out):  # pragma: no cover
    """Lowest row per column and centroid row of ``np.rot90(base, -k)``, from base's profiles.

    ``rot90(base, -1)[i, j] = base[rows - 1 - j, i]`` (shape (cols, rows)), ``-2``:
    ``base[rows - 1 - i, cols - 1 - j]``, ``-3``: ``base[j, cols - 1 - i]``. Writes the profile
    into `out` and returns (rows, cols, centroid row) of the turned footprint.
    """
    if k == 0:
        for j in range(cols):
            out[j] = low[j]
        return rows, cols, cy
    if k == 1:
        for j in range(rows):
            out[j] = left[rows - 1 - j]
        return cols, rows, cx
    if k == 2:
        for j in range(cols):
            h = high[cols - 1 - j]
            out[j] = _EMPTY if h < 0 else rows - 1 - h
        return rows, cols, (rows - 1) - cy
    for j in range(rows):
        r = right[j]
        out[j] = _EMPTY if r < 0 else cols - 1 - r
    return cols, rows, (cols - 1) - cx


@njit(cache=True, nogil=True)
def _equal_rows(a, i, j, n):  # pragma: no cover - compiled
    """``a[i, :n] == a[j, :n]`` everywhere (``np.array_equal`` of the two took 0.5 s of the first
    run's compile)."""
    for c in range(n):
        if a[i, c] != a[j, c]:
            return False
    return True


@njit(cache=True, nogil=True)
def _stable_order(keys, n):  # pragma: no cover - compiled
    """The indices of ``keys[:n]`` in ascending order, ties in index order: ``np.argsort(keys[:n],
    kind="mergesort")`` by insertion (n is a chart's orientations, at most a few dozen), where
    numba's merge sort took 2 s of the first run's compile."""
    out = np.empty(n, dtype=np.int64)
    for i in range(n):
        j = i
        while j > 0 and keys[out[j - 1]] > keys[i]:
            out[j] = out[j - 1]
            j -= 1
        out[j] = i
    return out


@njit(cache=True, nogil=True)
def _same_turns(base, rows, cols, k1, k2):  # pragma: no cover - compiled
    """Whether two quarter turns of `base` are the same footprint (shapes already equal)."""
    side = max(rows, cols)
    one = np.zeros((side, side), dtype=np.bool_)
    two = np.zeros((side, side), dtype=np.bool_)
    r, c = turned(base, rows, cols, k1, one)
    turned(base, rows, cols, k2, two)
    for i in range(r):
        for j in range(c):
            if one[i, j] != two[i, j]:
                return False
    return True


# ----------------------------------------------------------------------------------------------
# the canvas


@njit(cache=True, nogil=True)
def new_canvas(width, height, pad, block):  # pragma: no cover - compiled
    """Empty canvas arrays: (forbid, sky, coarse, prefix, max_free, free_bits); see the module
    docstring."""
    forbid = np.ones((height, width), dtype=np.bool_)
    for i in range(pad, height - pad):
        for j in range(pad, width - pad):
            forbid[i, j] = False
    sky = np.full(width, pad, dtype=np.int64)
    for j in range(pad):
        sky[j] = height
        sky[width - 1 - j] = height
    nr = (height + block - 1) // block
    nc = (width + block - 1) // block
    coarse = np.zeros((nr, nc), dtype=np.bool_)
    prefix = np.zeros((nr, nc + 1), dtype=np.int32)
    max_free = np.zeros(nr, dtype=np.int64)
    free_bits = np.zeros((nr, (nc + 63) // 64 + 1), dtype=np.uint64)  # a zero word past the end
    # np.int64(0), not 0, at the kernels' calls: a literal argument compiles another copy of
    # the callee (five such copies took 1.2 s of the first run's compile)
    _pool_rows(forbid, block, coarse, prefix, max_free, free_bits, np.int64(0), nr, np.int64(0), nc)
    return forbid, sky, coarse, prefix, max_free, free_bits


@njit(cache=True, nogil=True)
def _pool_rows(
    forbid, block, coarse, prefix, max_free, free_bits, r0, r1, c0, c1
):  # pragma: no cover - compiled
    """Recompute coarse cells [r0, r1) x [c0, c1) from `forbid` (texels past its edge count as
    forbidden), and the prefix sums, longest free runs and free-cell bit sets of those rows."""
    height, width = forbid.shape
    nc = coarse.shape[1]
    for R in range(r0, r1):
        for C in range(c0, c1):
            hit = False
            for i in range(R * block, (R + 1) * block):
                for j in range(C * block, (C + 1) * block):
                    if i >= height or j >= width or forbid[i, j]:
                        hit = True
                        break
                if hit:
                    break
            coarse[R, C] = hit
        run = 0
        best = 0
        for w in range(free_bits.shape[1]):
            free_bits[R, w] = 0
        for C in range(nc):
            prefix[R, C + 1] = prefix[R, C] + (1 if coarse[R, C] else 0)
            run = 0 if coarse[R, C] else run + 1
            best = max(best, run)
            if not coarse[R, C]:
                free_bits[R, C >> 6] |= np.uint64(1) << np.uint64(C & 63)
        max_free[R] = best


@njit(cache=True, nogil=True)
def _leading_edges(mask, rows, cols):  # pragma: no cover - compiled
    """The footprint's lower and left edges: its cells (i, j) whose neighbour below (i - 1, j),
    respectively to the left (i, j - 1), is not in it, i.e. the texels that a one-texel move
    down (left) newly covers, each list in row-major order. The lists are counted first, then
    filled (a rows * cols buffer would be megabytes for a large chart); each count is a pass
    that adds bytes, without a branch per cell: each placement rule 3-6% faster on 16 captured
    chart sets (BENCHMARKS.md section 0.1, session 19)."""
    m = mask.view(np.uint8)
    n_down = 0
    n_left = 0
    for j in range(cols if rows > 0 else 0):  # row 0: every cell is a lower edge
        n_down += m[0, j]
    for i in range(1, rows):
        c = 0
        for j in range(cols):
            c += m[i, j] & (m[i - 1, j] ^ 1)
        n_down += c
    for i in range(rows):
        c = np.int64(m[i, 0])
        for j in range(1, cols):
            c += m[i, j] & (m[i, j - 1] ^ 1)
        n_left += c
    down = np.empty((n_down, 2), dtype=np.int64)
    left = np.empty((n_left, 2), dtype=np.int64)
    n_down = 0
    n_left = 0
    for i in range(rows):
        for j in range(cols):
            if mask[i, j]:
                if i == 0 or not mask[i - 1, j]:
                    down[n_down, 0] = i
                    down[n_down, 1] = j
                    n_down += 1
                if j == 0 or not mask[i, j - 1]:
                    left[n_left, 0] = i
                    left[n_left, 1] = j
                    n_left += 1
    return down, left


#: A filled footprint of at least this many texels keeps its runs, and the trial reads off them
#: its turns' slide edges (`_turned_edges`) and coarse footprints (`_turned_coarse_runs`),
#: turning its mask only to place it; a smaller one's come from its turned mask
#: (`_leading_edges`, `coarse_runs`). The edges from the mask are faster below about 64 x 64
#: texels (per footprint, a disk, both lists: 48 x 48 texels 2.9 against 2.6 us, 64 x 64 3.8
#: against 4.3, 96 x 96 5.5 against 9.0); the coarse footprints take the same threshold.
_RUN_EDGES_MIN_TEXELS = 4096
#: The base footprint's cells that `_turned_edges` lists: a run's cells whose neighbour below
#: (`_BELOW_OPEN`) or above (`_ABOVE_OPEN`) is empty, the runs' first and last cells.
_BELOW_OPEN, _ABOVE_OPEN, _RUN_STARTS, _RUN_ENDS = 0, 1, 2, 3


@njit(cache=True, nogil=True)
def _turned_edges(ptr, start, end, rows, cols, k):  # pragma: no cover - compiled
    """`_leading_edges` of ``np.rot90(base, -k)`` from the runs of `base` (rows x cols): the
    same cells in another order (`_clear` does not depend on it), without a pass over the
    turned mask's texels (2.3x faster on the bone scan's, the cow's, brain-2k's and the
    airplane's footprints).

    The turned footprint's lower and left edges are, in `base`: for k = 0 the cells open below
    and the runs' starts; k = 1 the starts and the cells open above; k = 2 the cells open
    above and the runs' ends; k = 3 the ends and the cells open below (see `turned`).
    """
    # (no indexing of a tuple by k, nor slice assignments, in these kernels: numba compiles a
    # switch, or a shape check with its message, for each; seconds on a first run)
    if k == 0:
        lower, left = _BELOW_OPEN, _RUN_STARTS
    elif k == 1:
        lower, left = _RUN_STARTS, _ABOVE_OPEN
    elif k == 2:
        lower, left = _ABOVE_OPEN, _RUN_ENDS
    else:
        lower, left = _RUN_ENDS, _BELOW_OPEN
    none = np.empty((0, 2), dtype=np.int64)  # the counting passes write nothing
    return (
        _edge_cells(ptr, start, end, rows, cols, k, lower, none),
        _edge_cells(ptr, start, end, rows, cols, k, left, none),
    )


@njit(cache=True, nogil=True)
def _edge_cells(ptr, start, end, rows, cols, k, kind, none):  # pragma: no cover - compiled
    """The base cells of one `kind` (see `_turned_edges`), as cells of the k-turned footprint:
    counted, then written (``rot90(base, -k)[I, J]`` with (I, J) = (i, j), (j, rows - 1 - i),
    (rows - 1 - i, cols - 1 - j), (cols - 1 - j, i) for k = 0 .. 3). A row's cells open below
    (above) are its runs' cells that row i - 1 (i + 1) does not cover, found by walking the
    two rows' runs together. One function: each compiled function costs a first run time."""
    out = none
    n = 0
    ends = kind == _RUN_STARTS or kind == _RUN_ENDS
    for write in (False, True):
        if write:
            out = np.empty((n, 2), dtype=np.int64)
        n = 0
        for i in range(rows):
            q = i - 1 if kind == _BELOW_OPEN else i + 1
            g1 = ptr[q + 1] if not ends and 0 <= q < rows else 0
            g0 = ptr[q] if not ends and 0 <= q < rows else 0
            for r in range(ptr[i], ptr[i + 1]):
                a, b = start[r], end[r]
                if ends:  # one cell a run
                    a = b = start[r] if kind == _RUN_STARTS else end[r]
                while g0 < g1 and end[g0] < a:  # q's runs wholly left of this run
                    g0 += 1
                g = g0  # q's runs from here on: the next may cover a, a later one the rest
                while a <= b:
                    if g < g1 and start[g] <= a:  # a is covered by run g of row q: skip it
                        a = end[g] + 1
                        g += 1
                        continue
                    last = b if g >= g1 else min(b, start[g] - 1)
                    if write:
                        for j in range(a, last + 1):
                            m = n + j - a
                            if k == 0:
                                out[m, 0], out[m, 1] = i, j
                            elif k == 1:
                                out[m, 0], out[m, 1] = j, rows - 1 - i
                            elif k == 2:
                                out[m, 0], out[m, 1] = rows - 1 - i, cols - 1 - j
                            else:
                                out[m, 0], out[m, 1] = cols - 1 - j, i
                    n += last - a + 1
                    a = last + 1
    return out


@njit(cache=True, nogil=True)
def _clear(forbid, cells, row, col):  # pragma: no cover - compiled
    """Whether no cell of `cells`, shifted to (row, col), is forbidden."""
    for t in range(len(cells)):
        if forbid[row + cells[t, 0], col + cells[t, 1]]:
            return False
    return True


@njit(cache=True, nogil=True)
def slide(forbid, mask, rows, cols, row, col, max_steps):  # pragma: no cover - compiled
    """Move a fitting footprint down, then left, one texel at a time while it fits.

    Only the texels a move newly covers are tested: the footprint's lower (left) edges.
    """
    down, left = _leading_edges(mask, rows, cols)
    return _slide_edges(forbid, down, left, row, col, max_steps)


@njit(cache=True, nogil=True)
def _slide_edges(forbid, down, left, row, col, max_steps):  # pragma: no cover - compiled
    """`slide` with the footprint's lower and left edges given (computed once per orientation)."""
    steps = 0
    moved = True
    while moved and steps < max_steps:
        moved = False
        while row > 0 and _clear(forbid, down, row - 1, col):
            row -= 1
            steps += 1
            moved = True
        while col > 0 and _clear(forbid, left, row, col - 1):
            col -= 1
            steps += 1
            moved = True
    return row, col


@njit(cache=True, nogil=True)
def place(
    forbid, sky, coarse, prefix, max_free, free_bits, block, mask, rows, cols, row, col, pad
):  # pragma: no cover - compiled
    """Forbid the footprint dilated by `pad`, raise the skyline to its top, refresh the pool.

    Written straight into the canvas, run by run (no dilated copy): a run of footprint texels
    in a row forbids the rectangle `pad` texels around it, and a column's skyline rises to
    `pad` above the highest footprint texel within `pad` columns of it."""
    r0, c0 = row - pad, col - pad
    H, W = forbid.shape
    for i in range(rows):
        j = 0
        while j < cols:
            if not mask[i, j]:
                j += 1
                continue
            start = j
            while j < cols and mask[i, j]:
                j += 1
            lo, hi = max(col + start - pad, 0), min(col + j + pad, W)
            for ri in range(max(row + i - pad, 0), min(row + i + pad + 1, H)):
                forbid[ri, lo:hi] = True
    for j in range(cols):
        top = -1
        for i in range(rows - 1, -1, -1):
            if mask[i, j]:
                top = i
                break
        if top < 0:
            continue
        level = row + top + pad + 1
        for cj in range(max(col + j - pad, 0), min(col + j + pad + 1, sky.shape[0])):
            if level > sky[cj]:
                sky[cj] = level
    grown_rows, grown_cols = rows + 2 * pad, cols + 2 * pad
    R0 = max(r0, 0) // block
    R1 = min((min(r0 + grown_rows, H) + block - 1) // block, coarse.shape[0])
    C0 = max(c0, 0) // block
    C1 = min((min(c0 + grown_cols, W) + block - 1) // block, coarse.shape[1])
    _pool_rows(forbid, block, coarse, prefix, max_free, free_bits, R0, R1, C0, C1)


# ----------------------------------------------------------------------------------------------
# the two searches


@njit(cache=True, nogil=True)
def resting(bottom, cols, sky, sky_min, top, count, samples):  # pragma: no cover - compiled
    """The `count` lowest (then left-most) positions where the footprint rests on the skyline.

    At column j the footprint's lowest texels must clear the skyline of every column it covers:
    ``row(j) = max_c (sky[j + c] - bottom[c])``, at least 0 and at most `top`. Columns are
    scanned left to right; a position is dropped as soon as one of its terms already exceeds
    the `count`-th best row kept, testing about `samples` spread columns (the footprint's lowest
    one first) before the rest, so most positions cost a few comparisons; a run of
    `_SKY_BLOCK` positions is dropped at once when, for the lowest column or for one of the
    spread ones, the skyline's minimum under it across the run (`sky_min`: the minimum over
    `_SKY_BLOCK` columns from each column on) already lifts every position too high. The
    result is the exact `count` best. `bottom` holds the footprint's lowest row per column
    (`_EMPTY` for an empty column). Returns (found, rows, cols).
    """
    width = sky.shape[0]
    out_r = np.empty(count, dtype=np.int64)
    out_c = np.empty(count, dtype=np.int64)
    if cols > width:
        return 0, out_r, out_c
    lowest_col = 0
    for c in range(cols):
        if bottom[c] < bottom[lowest_col]:
            lowest_col = c
    step = max(1, cols // samples)
    probe = np.empty(cols // step + 2, dtype=np.int64)
    probe[0] = lowest_col
    n_probe = 1
    for c in range(0, cols, step):
        probe[n_probe] = c
        n_probe += 1
    found = 0
    hint = 0
    n_pos = width - cols + 1
    j = -1
    while j + 1 < n_pos:
        j += 1
        # a kept position must come lower than the worst kept (equal rows: left-most wins)
        limit = top if found < count else out_r[count - 1] - 1
        if j % _SKY_BLOCK == 0:
            # every position j .. j + B - 1 rests at least this high: a column's lowest texel
            # over the lowest skyline it meets across them
            low = sky_min[j + lowest_col] - bottom[lowest_col]
            t = 1
            while low <= limit and t < n_probe:
                low = max(low, sky_min[j + probe[t]] - bottom[probe[t]])
                t += 1
            if low > limit:
                j += _SKY_BLOCK - 1
                continue
        # the column that lifted the last position too high is, one column over, the likeliest
        # to lift this one too: test it first
        lift = 0
        if hint > 0:
            lift = max(sky[j + hint - 1] - bottom[hint - 1], 0)
            if lift > limit:
                hint -= 1
                continue
        for t in range(n_probe):
            v = sky[j + probe[t]] - bottom[probe[t]]
            if v > lift:
                lift = v
                if lift > limit:
                    hint = probe[t]
                    break
        if lift > limit:
            continue
        for c in range(cols):
            v = sky[j + c] - bottom[c]
            if v > lift:
                lift = v
                if lift > limit:
                    hint = c
                    break
        if lift > limit:
            continue
        pos = found
        while pos > 0 and lift < out_r[pos - 1]:
            pos -= 1
        for q in range(min(found, count - 1), pos, -1):
            out_r[q] = out_r[q - 1]
            out_c[q] = out_c[q - 1]
        out_r[pos] = lift
        out_c[pos] = j
        found = min(found + 1, count)
    return found, out_r, out_c


@njit(cache=True, nogil=True)
def coarse_runs(mask, rows, cols, block):  # pragma: no cover - compiled
    """The coarse footprint's runs of cells, as (row, first col, last col), widest first."""
    cr = (rows + block - 1) // block
    cc = (cols + block - 1) // block
    cm = np.zeros((cr, cc), dtype=np.bool_)
    for i in range(rows):
        R = i // block
        for C in range(cc):
            if cm[R, C]:  # already hit by an earlier texel row of this block row
                continue
            for j in range(C * block, min((C + 1) * block, cols)):
                if mask[i, j]:
                    cm[R, C] = True
                    break
    return _coarse_cell_runs(cm), cr, cc


@njit(cache=True, nogil=True)
def _turned_coarse_runs(ptr, start, end, rows, cols, k, block):  # pragma: no cover - compiled
    """`coarse_runs` of ``np.rot90(base, -k)`` from the runs of `base` (rows x cols), without
    turning it: each run marks the coarse cells its turned texels fall in (see `turned`)."""
    r, c = (rows, cols) if k % 2 == 0 else (cols, rows)
    cr = (r + block - 1) // block
    cc = (c + block - 1) // block
    cm = np.zeros((cr, cc), dtype=np.bool_)
    for i in range(rows):
        for q in range(ptr[i], ptr[i + 1]):
            a, b = start[q], end[q]
            if k == 0:  # turned row i, columns a .. b
                for C in range(a // block, b // block + 1):
                    cm[i // block, C] = True
            elif k == 2:  # row rows - 1 - i, columns cols - 1 - b .. cols - 1 - a
                for C in range((cols - 1 - b) // block, (cols - 1 - a) // block + 1):
                    cm[(rows - 1 - i) // block, C] = True
            elif k == 1:  # column rows - 1 - i, rows a .. b
                for R in range(a // block, b // block + 1):
                    cm[R, (rows - 1 - i) // block] = True
            else:  # column i, rows cols - 1 - b .. cols - 1 - a
                for R in range((cols - 1 - b) // block, (cols - 1 - a) // block + 1):
                    cm[R, i // block] = True
    return _coarse_cell_runs(cm), cr, cc


@njit(cache=True, nogil=True)
def _coarse_cell_runs(cm):  # pragma: no cover - compiled
    """The runs of a coarse footprint's cells `cm`, as (row, first col, last col), widest
    first (`coarse_runs`)."""
    cr, cc = cm.shape
    runs = np.empty((cr * ((cc + 1) // 2), 3), dtype=np.int64)
    n = 0
    widest = 0
    for i in range(cr):
        j = 0
        while j < cc:
            if cm[i, j]:
                start = j
                while j < cc and cm[i, j]:
                    j += 1
                runs[n, 0] = i
                runs[n, 1] = start
                runs[n, 2] = j - 1
                if j - start > runs[widest, 2] - runs[widest, 1] + 1:
                    widest = n
                n += 1
            else:
                j += 1
    runs = runs[:n].copy()
    # widest first: it is the run most likely to collide, so tests fail early (swapped entry by
    # entry: a row assignment ``runs[0] = runs[widest]`` took 2 s of the first run's compile)
    for k in range(3 if n else 0):
        runs[0, k], runs[widest, k] = runs[widest, k], runs[0, k]
    return runs


@njit(cache=True, nogil=True)
def _runs_of(bits, row, length, out):  # pragma: no cover - compiled
    """Bit p of `out`: coarse cells p .. p + length - 1 of the row are all free (word-wise)."""
    n_words = bits.shape[1]
    for w in range(n_words):
        out[w] = bits[row, w]
    have = 1
    while have < length:
        step = min(have, length - have)
        q, r = step >> 6, step & 63
        for w in range(n_words):  # out &= out >> step, words in increasing order
            lo = out[w + q] if w + q < n_words else np.uint64(0)
            if r:
                hi = out[w + q + 1] if w + q + 1 < n_words else np.uint64(0)
                lo = (lo >> np.uint64(r)) | (hi << np.uint64(64 - r))
            out[w] &= lo
        have += step


@njit(cache=True, nogil=True)
def holes(prefix, max_free, free_bits, runs, cr, cc, count):  # pragma: no cover - compiled
    """Per coarse column the lowest coarse row where the coarse footprint meets no forbidden
    cell; of those, the `count` lowest (then left-most). Returns (found, rows, cols).

    These are the first `count` fitting positions in row-major order (a column's first fit
    is its lowest), so rows are scanned upwards and the scan stops at the `count`-th fit.
    Rows whose longest free run is shorter than the footprint's widest run are skipped; in the
    others, the columns where that run fits come from the row's free-cell bits (64 cells a
    word), and only those positions are tested run by run with the row prefix sums, starting
    with the run that blocked the previous position.
    """
    nr = prefix.shape[0]
    nc = prefix.shape[1] - 1
    out_r = np.empty(count, dtype=np.int64)
    out_c = np.empty(count, dtype=np.int64)
    if cr > nr or cc > nc or len(runs) == 0 or count <= 0:
        return 0, out_r, out_c
    iw, w0, w1 = runs[0, 0], runs[0, 1], runs[0, 2]
    ww = w1 - w0 + 1
    taken = np.zeros(nc, dtype=np.bool_)
    starts = np.empty(free_bits.shape[1], dtype=np.uint64)
    found = 0
    hint = 0
    for y in range(nr - cr + 1):
        R = y + iw
        if max_free[R] < ww:
            continue
        _runs_of(free_bits, R, ww, starts)
        for w in range(len(starts)):
            word = starts[w]
            while word:
                bit = _trailing_zeros(word)  # the lowest set bit
                word &= word - np.uint64(1)  # clear it
                j = w * 64 + bit - w0  # the position whose widest run starts at this cell
                if j < 0 or j > nc - cc or taken[j]:
                    continue
                # the run that blocked the last position most likely blocks this one too
                Ru = y + runs[hint, 0]
                if prefix[Ru, j + runs[hint, 2] + 1] != prefix[Ru, j + runs[hint, 1]]:
                    continue
                ok = True
                for u in range(1, len(runs)):
                    Ru = y + runs[u, 0]
                    if prefix[Ru, j + runs[u, 2] + 1] != prefix[Ru, j + runs[u, 1]]:
                        ok = False
                        hint = u
                        break
                if ok:
                    taken[j] = True
                    out_r[found] = y
                    out_c[found] = j
                    found += 1
                    if found == count:
                        return found, out_r, out_c
    return found, out_r, out_c


# ----------------------------------------------------------------------------------------------
# one trial


@njit(cache=True, nogil=True)
def _turn_into(masks, q, flat, base_off, base_shape, ident, o):  # pragma: no cover - compiled
    """Write orientation o's footprint (its angle's base in `flat`, turned) into ``masks[q]``."""
    a = ident[o, 0]
    rows, cols = base_shape[a, 0], base_shape[a, 1]
    base = flat[base_off[a] : base_off[a + 1]].reshape((rows, cols))
    turned(base, rows, cols, ident[o, 1], masks[q])


@njit(cache=True, nogil=True)
def _append(buf, n, values):  # pragma: no cover - compiled
    """``buf[n : n + len(values)] = values``, in `buf` or a copy twice as large; returns (the
    buffer, n + len(values))."""
    end = n + len(values)
    if end > len(buf):
        grown = np.empty(max(2 * len(buf), end), dtype=buf.dtype)
        for k in range(n):  # loops, not slice copies: see _turned_edges
            grown[k] = buf[k]
        buf = grown
    for k in range(len(values)):
        buf[n + k] = values[k]
    return buf, end


@njit(cache=True, nogil=True)
def trial(
    Q,
    q_ptr,
    ext,
    elems,
    el_ptr,
    fill,
    entry_ptr,
    order,
    s,
    empty,
    pad,
    turns,
    rule,
    block,
    margin,
    eps,
    per_orientation,
    n_starts,
    n_candidates,
    samples,
    slide_steps,
    min_turning_side,
):  # pragma: no cover - compiled
    """Place every chart, in `order`, at scale s by one placement rule.

    Charts have entries ``entry_ptr[i] .. entry_ptr[i + 1]``, one per angle (the "holes" rule
    uses the first only): points ``Q[q_ptr[e]:q_ptr[e + 1]]`` (the chart turned by the angle,
    minimum corner at the origin, 3-D units) with extent ``ext[e]``; elements
    ``elems[el_ptr[i]:el_ptr[i + 1]]``, boundary edges when ``fill[i]`` (outline fill) else
    triangles. A footprint box is ``floor(extent * s + 2 margin) + 1`` texels, the chart
    centred in it. Returns (placed, result, need): how many charts were placed in order; per
    chart (angle entry, quarter turns, row, col, footprint rows, footprint cols); the texture
    side the layout needs (top-most footprint row + 1 + pad). `empty` is `new_canvas(width,
    height, pad, block)`, copied here (the same for every trial of a packing).
    """
    forbid, sky, coarse = empty[0].copy(), empty[1].copy(), empty[2].copy()
    prefix, max_free, free_bits = empty[3].copy(), empty[4].copy(), empty[5].copy()
    height, width = forbid.shape
    sky_min = np.empty(width, dtype=np.int64)
    _sky_minima(sky, sky_min, np.int64(0), width)  # not a literal 0: see new_canvas
    result = np.full((len(entry_ptr) - 1, 6), -1, dtype=np.int64)
    need = 0
    # the runs of the current chart's large filled footprints (`outline_runs`), kept for their
    # turns' edges (`_turned_edges`): per angle, where its row pointers and its runs start in
    # three buffers that grow as needed (a list of arrays per chart cost 3 us a chart: 5% of
    # the "rest" rule on 2,000 triangles)
    most = 1
    for c in range(len(entry_ptr) - 1):
        most = max(most, entry_ptr[c + 1] - entry_ptr[c])
    kept = np.zeros((most, 2), dtype=np.int64)
    kept_ptr = np.empty(1024, dtype=np.int64)
    kept_start = np.empty(1024, dtype=np.int64)
    kept_end = np.empty(1024, dtype=np.int64)
    for t in range(len(order)):
        i = order[t]
        e0 = entry_ptr[i]
        e1 = entry_ptr[i + 1] if rule == REST else e0 + 1
        # a footprint this small turns by quarter turns only: finer angles change few texels
        if max(ext[e0, 0], ext[e0, 1]) * s < min_turning_side:
            e1 = e0 + 1
        El = elems[el_ptr[i] : el_ptr[i + 1]]
        side = 1
        for e in range(e0, e1):
            side = max(side, int(np.floor(ext[e, 0] * s + 2 * margin)) + 1)
            side = max(side, int(np.floor(ext[e, 1] * s + 2 * margin)) + 1)
        n_or = (e1 - e0) * turns
        # every angle's footprint in one flat buffer (a C-contiguous block each)
        base_shape = np.zeros((e1 - e0, 2), dtype=np.int64)
        base_off = np.zeros(e1 - e0 + 1, dtype=np.int64)
        for e in range(e0, e1):
            base_shape[e - e0, 0] = int(np.floor(ext[e, 1] * s + 2 * margin)) + 1
            base_shape[e - e0, 1] = int(np.floor(ext[e, 0] * s + 2 * margin)) + 1
            base_off[e - e0 + 1] = base_off[e - e0] + base_shape[e - e0, 0] * base_shape[e - e0, 1]
        flat = np.zeros(base_off[e1 - e0], dtype=np.bool_)
        bottoms = np.empty((n_or, side), dtype=np.int64)
        shape = np.zeros((n_or, 2), dtype=np.int64)
        cy = np.zeros(n_or)
        ident = np.zeros((n_or, 2), dtype=np.int64)  # (angle entry, quarter turns)
        n_kept = np.int64(0)  # not a literal 0 (new_canvas): it is passed to _equal_rows
        n_ptr = n_run = 0  # nothing kept yet for this chart
        for e in range(e0, e1):
            a = e - e0
            n1, n0 = base_shape[a, 0], base_shape[a, 1]
            off0 = (n0 - ext[e, 0] * s) / 2
            off1 = (n1 - ext[e, 1] * s) / 2
            P = np.empty((q_ptr[e + 1] - q_ptr[e], 2))
            for v in range(P.shape[0]):
                P[v, 0] = Q[q_ptr[e] + v, 0] * s + off0
                P[v, 1] = Q[q_ptr[e] + v, 1] * s + off1
            base = flat[base_off[a] : base_off[a + 1]].reshape((n1, n0))
            if fill[i]:
                ptr, start, end = outline_runs(P, El, eps, n1, n0)
                low, high, left, right, cy0, cx0 = _run_profiles(base, ptr, start, end, n1, n0)
                if n1 * n0 >= _RUN_EDGES_MIN_TEXELS:  # kept for its turns' edges
                    kept[a, 0], kept[a, 1] = n_ptr, n_run
                    kept_ptr, n_ptr = _append(kept_ptr, n_ptr, ptr)
                    kept_start, _ = _append(kept_start, n_run, start)
                    kept_end, n_run = _append(kept_end, n_run, end)
            else:
                _raster_into(P, El, eps, base)
                low, high, left, right, cy0, cx0 = _profiles(base, n1, n0)
            first = n_kept
            for k in range(turns):
                r, c, y = _turned_bottom(
                    low, high, left, right, n1, n0, cy0, cx0, k, bottoms[n_kept]
                )
                duplicate = False
                for o in range(first, n_kept):  # a symmetric footprint: keep the first turn
                    if shape[o, 0] == r and shape[o, 1] == c and cy[o] == y:
                        if _equal_rows(bottoms, o, n_kept, c):
                            if _same_turns(base, n1, n0, ident[o, 1], k):
                                duplicate = True
                                break
                if duplicate:
                    continue
                shape[n_kept, 0] = r
                shape[n_kept, 1] = c
                cy[n_kept] = y
                ident[n_kept, 0] = a
                ident[n_kept, 1] = k
                n_kept += 1
        # turned masks are written out only for the orientations that are tried
        n_slots = min(n_kept, n_starts) if rule == REST else n_kept
        masks = np.empty((n_slots, side, side), dtype=np.bool_)  # `turned` writes [:r, :c]
        slot = np.full(n_kept, -1, dtype=np.int64)
        # per slot, the lower and left edges that `_slide_edges` tests (filled on first use)
        no_edge = np.empty((0, 2), dtype=np.int64)
        downs = [no_edge for _ in range(n_slots)]
        lefts = [no_edge for _ in range(n_slots)]
        has_edges = np.zeros(n_slots, dtype=np.bool_)
        has_mask = np.zeros(n_slots, dtype=np.bool_)
        used = 0
        # starting points (orientation, row, col), in the order they are tried
        if rule == REST:
            # the best over all orientations, by (centroid row, col, orientation, row)
            s_key = np.full(n_starts, np.inf)
            s_col = np.zeros(n_starts, dtype=np.int64)
            s_or = np.zeros(n_starts, dtype=np.int64)
            s_row = np.zeros(n_starts, dtype=np.int64)
            n_s = 0
            # Orientations with a low centroid first: their starts fill the list soonest with
            # low keys, so `top` prunes the others' scans sooner. The starts kept are the
            # n_starts best in the order of `_before` whatever the order the orientations are
            # scanned in (a position above `top` is worse than every start kept): the same
            # layouts (uv hashes of 13 captured chart sets), 3-4% less time in this rule on
            # 2,000 triangles and 300 spheres.
            by_cy = _stable_order(cy, n_kept)
            for o in by_cy:
                r, c = shape[o, 0], shape[o, 1]
                top = height - pad - r
                if n_s == n_starts:  # a start must come no higher than the worst one kept
                    top = min(top, int(np.floor(s_key[n_starts - 1] - cy[o])))
                got, rr, cc = resting(bottoms[o], c, sky, sky_min, top, per_orientation, samples)
                for g in range(got):
                    key = rr[g] + cy[o]
                    pos = n_s
                    while pos > 0 and _before(
                        key,
                        cc[g],
                        o,
                        rr[g],
                        s_key[pos - 1],
                        s_col[pos - 1],
                        s_or[pos - 1],
                        s_row[pos - 1],
                    ):
                        pos -= 1
                    if pos >= n_starts:
                        continue
                    for q in range(min(n_s, n_starts - 1), pos, -1):
                        s_key[q] = s_key[q - 1]
                        s_col[q] = s_col[q - 1]
                        s_or[q] = s_or[q - 1]
                        s_row[q] = s_row[q - 1]
                    s_key[pos] = key
                    s_col[pos] = cc[g]
                    s_or[pos] = o
                    s_row[pos] = rr[g]
                    n_s = min(n_s + 1, n_starts)
        else:
            s_or = np.zeros(n_kept * n_candidates, dtype=np.int64)
            s_row = np.zeros(n_kept * n_candidates, dtype=np.int64)
            s_col = np.zeros(n_kept * n_candidates, dtype=np.int64)
            n_s = 0
            for o in range(n_kept):
                a = ident[o, 0]
                slot[o] = o
                if fill[i] and shape[o, 0] * shape[o, 1] >= _RUN_EDGES_MIN_TEXELS:
                    n1, n0 = base_shape[a, 0], base_shape[a, 1]
                    p0, r0 = kept[a, 0], kept[a, 1]
                    runs, cr, cc = _turned_coarse_runs(
                        kept_ptr[p0 : p0 + n1 + 1], kept_start[r0:], kept_end[r0:], n1, n0,
                        ident[o, 1], block,
                    )  # fmt: skip
                else:
                    _turn_into(masks, o, flat, base_off, base_shape, ident, o)
                    has_mask[o] = True
                    runs, cr, cc = coarse_runs(masks[o], shape[o, 0], shape[o, 1], block)
                got, rr, cols = holes(prefix, max_free, free_bits, runs, cr, cc, n_candidates)
                for g in range(got):
                    s_or[n_s] = o
                    s_row[n_s] = rr[g] * block
                    s_col[n_s] = cols[g] * block
                    n_s += 1
        # slide each start down and left; the lowest centroid wins
        best_o = np.int64(-1)  # not literals (see new_canvas): they are passed to kernels
        best_key = np.inf
        best_col = np.int64(0)
        best_row = np.int64(0)
        zero = np.int64(0)  # the rows _before does not compare
        for g in range(n_s):
            o, row, col = s_or[g], s_row[g], s_col[g]
            r, c = shape[o, 0], shape[o, 1]
            from_runs = fill[i] and r * c >= _RUN_EDGES_MIN_TEXELS  # its runs were kept
            if slot[o] < 0:
                slot[o] = used
                used += 1
                if not from_runs:  # its edges come from its mask: turned now
                    _turn_into(masks, slot[o], flat, base_off, base_shape, ident, o)
                    has_mask[slot[o]] = True
            q = slot[o]
            # every start fits by construction: a resting position clears the skyline in every
            # column, and a hole's coarse footprint meets no coarse cell holding a forbidden texel
            if not has_edges[q]:
                a = ident[o, 0]
                if from_runs:
                    n1, n0 = base_shape[a, 0], base_shape[a, 1]
                    p0, r0 = kept[a, 0], kept[a, 1]
                    downs[q], lefts[q] = _turned_edges(
                        kept_ptr[p0 : p0 + n1 + 1], kept_start[r0:], kept_end[r0:], n1, n0,
                        ident[o, 1],
                    )  # fmt: skip
                else:
                    downs[q], lefts[q] = _leading_edges(masks[q], r, c)
                has_edges[q] = True
            row, col = _slide_edges(forbid, downs[q], lefts[q], row, col, slide_steps)
            key = row + cy[o]
            if best_o < 0 or _before(key, col, o, zero, best_key, best_col, best_o, zero):
                best_o, best_key, best_col, best_row = o, key, col, row
        if best_o < 0:
            return t, result, need
        r, c = shape[best_o, 0], shape[best_o, 1]
        if not has_mask[slot[best_o]]:  # a large footprint's mask: turned for its placing only
            _turn_into(masks, slot[best_o], flat, base_off, base_shape, ident, best_o)
        place(
            forbid,
            sky,
            coarse,
            prefix,
            max_free,
            free_bits,
            block,
            masks[slot[best_o]],
            r,
            c,
            best_row,
            best_col,
            pad,
        )
        _sky_minima(sky, sky_min, best_col - pad, best_col + c + pad)
        result[i, 0] = ident[best_o, 0]
        result[i, 1] = ident[best_o, 1]
        result[i, 2] = best_row
        result[i, 3] = best_col
        result[i, 4] = r
        result[i, 5] = c
        need = max(need, best_row + r + pad)
    return len(order), result, need
