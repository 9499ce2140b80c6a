"""Conservative rasterization of uv triangles on a texel grid (used by pack, export and tests).

A triangle *touches* a texel when the closed triangle and the closed texel square intersect,
widened by a tolerance `eps` (texels). The kernels are compiled with numba (``cache=True``: the
machine code is kept beside this file after the first run), because the packer rasterizes every
chart in up to 24 orientations for every scale it tries, and the per-row work of a triangle is
a few comparisons that numpy could only batch at the price of large temporary arrays.

Conventions: a texel ``(i, j)`` of a ``width x height`` texture (``resolution x resolution``
unless trimmed, see ``PackConfig.trim``) covers ``[j, j + 1] / width x [i, i + 1] / height`` in
uv, i.e. grids are indexed ``[row = v, col = u]`` with row 0 at v = 0.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

__all__ = [
    "CHECK_EPS",
    "boundary_edges",
    "dilate",
    "fill_outline",
    "footprint_conflicts",
    "rasterize_footprint",
    "rasterize_triangles",
    "texture_size",
]

# Tolerance (texels) of the public rasterizer: anything within it of a texel touches the texel.
CHECK_EPS = 1e-7


@njit(cache=True, nogil=True)
def _raster_into(P, F, eps, mask):  # pragma: no cover - compiled
    """OR the texels touched by triangles ``P[F]`` (texel coordinates) into `mask`.

    Exact for closed sets, row by row: the part of a triangle inside the slab of texel row i
    (``i <= y <= i + 1``) is convex, so it touches the texels of that row that its x-range
    meets (`_slab_span`). Degenerate triangles keep their segments.
    """
    rows, cols = mask.shape
    for t in range(F.shape[0]):
        a, b, c = F[t, 0], F[t, 1], F[t, 2]
        ymin = min(P[a, 1], P[b, 1], P[c, 1])
        ymax = max(P[a, 1], P[b, 1], P[c, 1])
        lo = max(int(np.floor(ymin - eps)), 0)
        hi = min(int(np.floor(ymax + eps)), rows - 1)
        for row in range(lo, hi + 1):
            xmin, xmax = _slab_span(P, a, b, c, row, eps)
            if xmin <= xmax:
                x0 = max(int(np.floor(xmin - eps)), 0)
                x1 = min(int(np.floor(xmax + eps)), cols - 1)
                for x in range(x0, x1 + 1):
                    mask[row, x] = True


@njit(cache=True, nogil=True)
def _slab_span(P, a, b, c, row, eps):  # pragma: no cover - compiled
    """The x-range (xmin, xmax) of triangle ``P[[a, b, c]]`` inside the slab of texel row
    `row` widened by `eps` (``row - eps <= y <= row + 1 + eps``), or (inf, -inf) when it misses
    the slab: from the vertices inside the slab and the edges' crossings of its two lines."""
    y0 = row - eps
    y1 = row + 1 + eps
    xmin = np.inf
    xmax = -np.inf
    for v in range(3):
        iv = a if v == 0 else (b if v == 1 else c)
        iw = b if v == 0 else (c if v == 1 else a)
        xv, yv = P[iv, 0], P[iv, 1]
        xw, yw = P[iw, 0], P[iw, 1]
        if yv >= y0 and yv <= y1:
            xmin = min(xmin, xv)
            xmax = max(xmax, xv)
        dy = yw - yv
        if dy != 0:
            slope = (xw - xv) / dy
            ylow, yhigh = min(yv, yw), max(yv, yw)
            for line in (y0, y1):
                if line >= ylow and line <= yhigh:
                    x = xv + (line - yv) * slope
                    xmin = min(xmin, x)
                    xmax = max(xmax, x)
    return xmin, xmax


@njit(cache=True, nogil=True)
def _fill_into(P, B, eps, mask):  # pragma: no cover - compiled
    """OR the texels of the union of counter-clockwise triangles, from its outline B, into mask
    (the runs of `outline_runs`)."""
    rows, cols = mask.shape
    ptr, start, end = outline_runs(P, B, eps, rows, cols)
    for row in range(rows):
        for r in range(ptr[row], ptr[row + 1]):
            for col in range(start[r], end[r] + 1):
                mask[row, col] = True


@njit(cache=True, nogil=True)
def outline_runs(P, B, eps, rows, cols):  # pragma: no cover - compiled
    """The texels of the union of counter-clockwise triangles, from its outline's edges B (the
    first two columns are read), as runs: row i holds ``[start[r], end[r]]`` (inclusive) for
    r in ``ptr[i] .. ptr[i + 1] - 1``, sorted and disjoint, on a ``rows x cols`` grid.

    A texel touches the union when it touches a boundary edge (an edge as a degenerate
    triangle, `_slab_span`), or else when its centre lies inside, where the winding number of
    the outline is positive (counter-clockwise: the outline goes down on the left side of the
    inside, up on the right). Per row, the edges' x-ranges and their crossings of the row's
    centre line are sorted and swept into runs, so the work is proportional to the outline,
    not to the area: the packer fills every chart in every angle of every trial (on the bone
    scan's 78 footprints, 6.9 million texels: 11.9 -> 4.5 ms with the packer's profiles).
    """
    ne = B.shape[0]
    # per edge the rows it touches (lo, hi) and those whose centre line it crosses; per row
    # the touches' and crossings' counts, then offsets (no slice assignment in this module's
    # kernels: numba compiles a shape check with its message for each, seconds on a first run)
    lo_t = np.empty(ne, dtype=np.int64)
    hi_t = np.empty(ne, dtype=np.int64)
    lo_x = np.empty(ne, dtype=np.int64)
    hi_x = np.empty(ne, dtype=np.int64)
    c_t = np.zeros(rows + 1, dtype=np.int64)
    c_x = np.zeros(rows + 1, dtype=np.int64)
    for e in range(ne):
        ya, yb = P[B[e, 0], 1], P[B[e, 1], 1]
        ymin, ymax = min(ya, yb), max(ya, yb)
        lo_t[e] = max(int(np.floor(ymin - eps)), 0)
        hi_t[e] = min(int(np.floor(ymax + eps)), rows - 1)
        # the crossings of the centre lines y = i + 1/2 with min(ya, yb) <= y < max(ya, yb)
        lo_x[e] = max(int(np.ceil(ymin - 0.5)), 0)
        hi_x[e] = min(int(np.ceil(ymax - 0.5)) - 1, rows - 1)
        for row in range(lo_t[e], hi_t[e] + 1):
            c_t[row + 1] += 1
        for row in range(lo_x[e], hi_x[e] + 1):
            c_x[row + 1] += 1
    for row in range(rows):
        c_t[row + 1] += c_t[row]
        c_x[row + 1] += c_x[row]
    n_t, n_x = c_t[rows], c_x[rows]
    # touches (first, last texel), crossings (first centre right of it, winding step), the
    # inside runs of one row, the runs found
    t_first, t_last = np.empty(n_t, dtype=np.int64), np.empty(n_t, dtype=np.int64)
    x_col, x_step = np.empty(n_x, dtype=np.int64), np.empty(n_x, dtype=np.int64)
    in_start, in_end = np.empty(n_x, dtype=np.int64), np.empty(n_x, dtype=np.int64)
    start, end = np.empty(n_t + n_x, dtype=np.int64), np.empty(n_t + n_x, dtype=np.int64)
    s_t = np.empty(rows, dtype=np.int64)
    s_x = np.empty(rows, dtype=np.int64)
    for row in range(rows):
        s_t[row] = c_t[row]
        s_x[row] = c_x[row]
    for e in range(ne):
        ia, ib = B[e, 0], B[e, 1]
        for row in range(lo_t[e], hi_t[e] + 1):
            xmin, xmax = _slab_span(P, ia, ib, ib, row, eps)
            q = s_t[row]
            t_first[q], t_last[q] = 1, 0  # empty, unless the edge meets the slab
            if xmin <= xmax:
                t_first[q] = max(int(np.floor(xmin - eps)), 0)
                t_last[q] = min(int(np.floor(xmax + eps)), cols - 1)
            s_t[row] = q + 1
        xa, ya = P[ia, 0], P[ia, 1]
        xb, yb = P[ib, 0], P[ib, 1]
        step = 1 if yb < ya else -1
        for row in range(lo_x[e], hi_x[e] + 1):
            x = xa + (row + 0.5 - ya) / (yb - ya) * (xb - xa)
            q = s_x[row]
            x_col[q] = min(max(int(np.ceil(x - 0.5)), 0), cols)
            x_step[q] = step
            s_x[row] = q + 1
    ptr = np.zeros(rows + 1, dtype=np.int64)
    n = 0
    for row in range(rows):
        t0, t1 = c_t[row], c_t[row + 1]
        x0, x1 = c_x[row], c_x[row + 1]
        _sort_pairs(t_first, t_last, t0, t1)
        _sort_pairs(x_col, x_step, x0, x1)
        # the inside: texels j whose running winding (the steps at columns <= j) is positive
        n_in = 0
        w = 0
        k = x0
        while k < x1:
            col = x_col[k]
            while k < x1 and x_col[k] == col:
                w += x_step[k]
                k += 1
            if col >= cols:
                break
            if w > 0:
                last = min(x_col[k] - 1 if k < x1 else cols - 1, cols - 1)
                if n_in > 0 and in_end[n_in - 1] + 1 >= col:
                    in_end[n_in - 1] = max(in_end[n_in - 1], last)
                else:
                    in_start[n_in], in_end[n_in] = col, last
                    n_in += 1
        # the union of the touches (sorted by their first texel) and the inside runs
        i, j = t0, 0
        have = False
        a0, b0 = 0, 0
        while i < t1 or j < n_in:
            if j >= n_in or (i < t1 and t_first[i] <= in_start[j]):
                a, b = t_first[i], t_last[i]
                i += 1
            else:
                a, b = in_start[j], in_end[j]
                j += 1
            if a > b:
                continue
            if have and a <= b0 + 1:
                b0 = max(b0, b)
                continue
            if have:
                start[n], end[n] = a0, b0
                n += 1
            a0, b0, have = a, b, True
        if have:
            start[n], end[n] = a0, b0
            n += 1
        ptr[row + 1] = n
    return ptr, start[:n], end[:n]


@njit(cache=True, nogil=True)
def _sort_pairs(key, value, lo, hi):  # pragma: no cover - compiled
    """Sort ``key[lo:hi]`` ascending in place, `value` along (Shell sort, Knuth's gaps: a row
    holds a few entries, or hundreds where an outline runs along it; numba's sorts cost
    seconds of the first run's compile)."""
    n = hi - lo
    gap = 1
    while 3 * gap + 1 < n:
        gap = 3 * gap + 1
    while gap >= 1:
        for i in range(lo + gap, hi):
            k, v = key[i], value[i]
            j = i
            while j >= lo + gap and key[j - gap] > k:
                key[j] = key[j - gap]
                value[j] = value[j - gap]
                j -= gap
            key[j] = k
            value[j] = v
        gap //= 3


def rasterize_triangles(P: np.ndarray, F: np.ndarray, shape: tuple[int, int], eps: float):
    """Texels of a ``shape = (rows, cols)`` grid touched by triangles with texel coordinates P."""
    mask = np.zeros(shape, dtype=np.bool_)
    if len(F):
        _raster_into(
            np.ascontiguousarray(P, dtype=np.float64), np.ascontiguousarray(F, np.int64), eps, mask
        )
    return mask


def fill_outline(P: np.ndarray, B: np.ndarray, shape: tuple[int, int], eps: float) -> np.ndarray:
    """The texels `rasterize_triangles` gives for a chart, from its boundary edges B alone.

    B comes from :func:`boundary_edges` of counter-clockwise triangles; texel for texel the
    same mask as rasterizing every triangle.
    """
    mask = np.zeros(shape, dtype=np.bool_)
    _fill_into(
        np.ascontiguousarray(P, dtype=np.float64), np.ascontiguousarray(B, np.int64), eps, mask
    )
    return mask


def boundary_edges(F: np.ndarray) -> np.ndarray | None:
    """Directed boundary edges of counter-clockwise triangles, or None if a fill can't use them.

    The outline fill needs every interior edge to be used once in each direction (then the
    two triangles of an interior edge lie on its two sides, and the union's outline is made of
    boundary edges only). Returns None when a directed edge repeats or an edge has more than
    two triangles.
    """
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    n = int(F.max()) + 1
    directed = E[:, 0] * n + E[:, 1]
    if len(np.unique(directed)) != len(directed):
        return None
    undirected = np.minimum(E[:, 0], E[:, 1]) * n + np.maximum(E[:, 0], E[:, 1])
    _, inverse, counts = np.unique(undirected, return_inverse=True, return_counts=True)
    if counts.max() > 2:
        return None
    return E[counts[inverse.ravel()] == 1]


@njit(cache=True, nogil=True)
def dilate_kernel(mask, radius):  # pragma: no cover - compiled
    """Square (Chebyshev) dilation by `radius`; the result grows by radius on every side."""
    rows, cols = mask.shape
    wide = np.zeros((rows, cols + 2 * radius), dtype=np.bool_)
    for i in range(rows):
        for j in range(cols):
            if mask[i, j]:
                for d in range(2 * radius + 1):
                    wide[i, j + d] = True
    out = np.zeros((rows + 2 * radius, cols + 2 * radius), dtype=np.bool_)
    for i in range(rows):
        for j in range(cols + 2 * radius):
            if wide[i, j]:
                for d in range(2 * radius + 1):
                    out[i + d, j] = True
    return out


def dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Square (Chebyshev) dilation by `radius` texels; the result grows by radius per side."""
    return dilate_kernel(np.ascontiguousarray(mask, dtype=np.bool_), int(radius))


def texture_size(resolution: int | tuple[int, int]) -> tuple[int, int]:
    """A texture's ``(width, height)`` in texels from a side (a square) or a pair."""
    if np.ndim(resolution) == 0:
        return int(resolution), int(resolution)
    width, height = resolution
    return int(width), int(height)


def rasterize_footprint(
    uv: np.ndarray, F: np.ndarray, *, resolution: int | tuple[int, int], eps: float = CHECK_EPS
) -> np.ndarray:
    """Conservative footprint of one chart on a ``resolution x resolution`` texture (or a
    ``width x height`` one: ``resolution=(width, height)``).

    Parameters
    ----------
    uv : (n, 2) float ndarray
        Chart coordinates in the unit square (parts outside are clipped).
    F : (m, 3) int ndarray
        Triangles, indices into `uv`.
    resolution : int or (int, int)
        Texels per side, or the texture's (width, height).
    eps : float
        Tolerance in texels: a texel closer than `eps` to a triangle counts as touched.

    Returns
    -------
    mask : (height, width) bool ndarray
        ``mask[i, j]`` is True when a triangle touches texel ``[j, j+1] / width x [i, i+1] /
        height`` (row index along v).
    """
    W, H = texture_size(resolution)
    uv = np.asarray(uv, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    return rasterize_triangles(uv * np.array([W, H], dtype=np.float64), F, (H, W), eps)


def footprint_conflicts(
    uvs: Sequence[np.ndarray],
    faces: Sequence[np.ndarray],
    *,
    resolution: int | tuple[int, int],
    padding: int = 0,
) -> int:
    """Count the texels that break the padding rule of a packed atlas.

    A footprint texel of a chart is counted when it lies within `padding` texels (Chebyshev
    distance) of another chart's footprint or of the texture's border, or outside the texture.
    With ``padding=0`` this counts texels shared by two charts: a positive count proves that the
    conservative footprints overlap.

    Parameters
    ----------
    uvs : sequence of (n_i, 2) float ndarray
        Chart coordinates, meant to lie in the unit square.
    faces : sequence of (m_i, 3) int ndarray
        Chart triangles.
    resolution : int or (int, int)
        Texels per side, or the texture's (width, height) (``PackResult.size``).
    padding : int
        Empty texels required between charts and to the border.

    Returns
    -------
    int
        Number of offending (chart, texel) pairs; 0 for a valid layout.
    """
    W, H = texture_size(resolution)
    p = int(padding)
    texels = np.array([W, H], dtype=np.float64)
    # a canvas with a margin, so that footprints past the border are still seen
    m = p + 2
    size = (H + 2 * m, W + 2 * m)
    count = np.zeros(size, dtype=np.int32)
    windows = []
    bad = 0
    for uv, F in zip(uvs, faces, strict=True):  # loop over charts
        P = np.asarray(uv, dtype=np.float64) * texels
        F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
        outside = (P < 2 - m) | (P > texels + m - 2)
        if np.any(outside):  # far outside the texture: count every vertex, skip the raster
            bad += int(np.count_nonzero(outside.any(axis=1)))
            windows.append(None)
            continue
        lo = np.floor(P.min(axis=0)).astype(np.int64) - 1
        hi = np.floor(P.max(axis=0)).astype(np.int64) + 2
        shape = (int(hi[1] - lo[1]), int(hi[0] - lo[0]))
        mask = rasterize_triangles(P - lo, F, shape, CHECK_EPS)
        grown = dilate(mask, p)
        r0, c0 = int(lo[1]) + m - p, int(lo[0]) + m - p
        r0c, c0c = max(r0, 0), max(c0, 0)
        r1c, c1c = min(r0 + grown.shape[0], size[0]), min(c0 + grown.shape[1], size[1])
        count[r0c:r1c, c0c:c1c] += grown[r0c - r0 : r1c - r0, c0c - c0 : c1c - c0]
        windows.append((mask, grown, r0, c0))
    allowed = np.zeros(size, dtype=bool)
    allowed[m + p : m + H - p, m + p : m + W - p] = True
    for w in windows:
        if w is None:
            continue
        mask, grown, r0, c0 = w
        rows, cols = mask.shape
        r, c = r0 + p, c0 + p  # the mask's own window, inside the canvas by the margin test
        others = count[r : r + rows, c : c + cols] - grown[p : p + rows, p : p + cols]
        inside = allowed[r : r + rows, c : c + cols]
        bad += int(np.count_nonzero(mask & ((others > 0) | ~inside)))
    return bad
