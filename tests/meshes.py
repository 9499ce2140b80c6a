"""Meshes built in code for the tests: regular grids mapped onto analytic surfaces."""

from __future__ import annotations

import numpy as np


def tri_grid(nx: int, ny: int, *, width: float = 1.0, height: float | None = None):
    """A regular (nearly equilateral) triangulation of a rectangle in the z = 0 plane.

    Returns ``V`` (nx * ny, 3) and ``F`` (2 (nx - 1)(ny - 1), 3), counter-clockwise seen from +z.
    """
    dy = width / (nx - 1) * np.sqrt(3) / 2
    height = dy * (ny - 1) if height is None else height
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = i * width / (nx - 1) + 0.5 * (j % 2) * width / (nx - 1)
    x = x / x.max() * width
    y = j * height / (ny - 1)
    V = np.stack([x.ravel(), y.ravel(), np.zeros(nx * ny)], axis=1)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b = idx[:-1, :-1], idx[1:, :-1]
    c, d = idx[1:, 1:], idx[:-1, 1:]
    even = (np.arange(ny - 1) % 2 == 0)[None, :].repeat(nx - 1, axis=0)
    # Alternate the diagonal with the row offset so that triangles stay near-equilateral.
    t1 = np.where(even[..., None], np.stack([a, b, d], -1), np.stack([a, b, c], -1))
    t2 = np.where(even[..., None], np.stack([b, c, d], -1), np.stack([a, c, d], -1))
    F = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)])
    return V, F.astype(np.int64)


def cylinder_patch(nx=30, ny=20, *, radius=1.0, angle=np.pi, length=2.0):
    V, F = tri_grid(nx, ny, width=radius * angle, height=length)
    th = V[:, 0] / radius
    return np.stack([radius * np.cos(th), radius * np.sin(th), V[:, 1]], axis=1), F


def cone_patch(nx=30, ny=15, *, apex_angle=0.5, r0=1.0, r1=2.0, sector=2.0):
    """A developable cone patch: a planar annular sector (r in [r0, r1]) rolled up."""
    V, F = tri_grid(nx, ny)
    r = r0 + (r1 - r0) * V[:, 1] / V[:, 1].max()
    phi = sector * V[:, 0]  # angle in the unrolled plane
    s = np.sin(apex_angle)  # cone's circumference factor
    theta = phi / s
    return np.stack([r * s * np.cos(theta), r * s * np.sin(theta), r * np.cos(apex_angle)], 1), F


def spherical_cap(nx=25, ny=25, *, extent=1.6):
    V, F = tri_grid(nx, ny, width=extent, height=extent)
    p = V[:, :2] - extent / 2
    P = np.c_[p, np.ones(len(p))]
    return P / np.linalg.norm(P, axis=1, keepdims=True), F


def saddle(nx=25, ny=25, *, k=1.0):
    V, F = tri_grid(nx, ny, width=2.0, height=2.0)
    V = V - [1.0, 1.0, 0.0]
    V[:, 2] = k * (V[:, 0] ** 2 - V[:, 1] ** 2) / 2
    return V, F


def folded_strip(nx=160, ny=10, *, folds=3, amplitude=0.12, width=0.25):
    """An accordion: a developable strip, z = a sin(2 pi folds x), evenly triangulated along its
    arclength so the triangles stay well shaped while the walls of the folds come close."""
    t = np.linspace(0, 1, 20001)
    z = amplitude * np.sin(2 * np.pi * folds * t)
    arc = np.r_[0, np.cumsum(np.hypot(np.diff(t), np.diff(z)))]
    V, F = tri_grid(nx, ny, width=arc[-1], height=width)
    x = np.interp(V[:, 0], arc, t)
    return np.stack([x, V[:, 1], amplitude * np.sin(2 * np.pi * folds * x)], axis=1), F


def rigid(V, *, seed=0, scale=1.0):
    """A random rotation (det +1), translation and uniform scale applied to V."""
    rng = np.random.default_rng(seed)
    Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return scale * V @ Q.T + rng.standard_normal(3)


def procrustes_residual(X, Y):
    """RMS distance between 2-D point sets after the best rotation (no reflection) and shift."""
    X = X - X.mean(0)
    Y = Y - Y.mean(0)
    U, _, Vt = np.linalg.svd(X.T @ Y)
    D = np.diag([1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return float(np.sqrt(((X @ R - Y) ** 2).sum(1).mean()))


def plate_with_holes(nx=24, ny=12, *, holes=((5, 9, 4, 8), (15, 19, 4, 8)), thickness=0.3):
    """A CAD-like closed part: a rectangular plate with square through-holes (genus = #holes).

    Sharp 90-degree edges all round. ``holes`` are cell ranges (x0, x1, y0, y1) removed from the
    plate's nx-by-ny cell grid.
    """
    from segparam.mesh import boundary_edges

    i, j = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="ij")
    P = np.stack([i.ravel(), j.ravel()], 1).astype(float) / nx * 4
    ci, cj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    keep = np.ones((nx, ny), bool)
    for x0, x1, y0, y1 in holes:
        keep[x0:x1, y0:y1] = False
    ci, cj = ci[keep], cj[keep]
    a = ci * (ny + 1) + cj
    b, c, d = a + (ny + 1), a + (ny + 1) + 1, a + 1
    top = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    used, top = np.unique(top, return_inverse=True)
    top = top.reshape(-1, 3)
    P = P[used]
    n = len(P)
    V = np.vstack([np.c_[P, np.full(n, thickness)], np.c_[P, np.zeros(n)]])
    bottom = top[:, ::-1] + n
    B = boundary_edges(top)  # directed along the top's winding
    walls = np.concatenate(
        [
            np.stack([B[:, 1], B[:, 0], B[:, 0] + n], 1),
            np.stack([B[:, 1], B[:, 0] + n, B[:, 1] + n], 1),
        ]
    )
    return V, np.concatenate([top, bottom, walls]).astype(np.int64)


def bulb(theta_max=120.0, n_around=48, n_down=24):
    """A unit sphere from its north pole down past the equator to ``theta_max`` degrees, open
    there: a knob (9.2 rad of curvature at 120 degrees) whose halves hold too much each to map
    within the default stretch target."""
    th = np.radians(np.linspace(0, theta_max, n_down + 1))[1:]
    ph = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    V = np.vstack([[0.0, 0.0, 1.0], ring.reshape(-1, 3)])
    j = np.arange(n_around)
    fan = np.column_stack([np.zeros(n_around, dtype=np.int64), 1 + j, 1 + (j + 1) % n_around])
    i = np.arange(n_down - 1)[:, None]
    a = 1 + i * n_around + j
    b = 1 + i * n_around + (j + 1) % n_around
    quads = np.stack([np.stack([a, a + n_around, b + n_around], -1),
                      np.stack([a, b + n_around, b], -1)], 2).reshape(-1, 3)  # fmt: skip
    return V, np.vstack([fan, quads]).astype(np.int64)
