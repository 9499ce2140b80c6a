"""Repeated parts: connected pieces that are copies of one another are charted once.

Models with hundreds of parts repeat most of them: the bolts, rivets and washers of a CAD
assembly, the leaves or props of a game model, each a copy of one part moved into place. A
piece whose faces are another's, in the same order, and whose vertices are that piece's moved
by one similarity (a rotation, a uniform scale and a translation: no mirroring) gets that
piece's charts: the segmentation's labels, each chart's map scaled by the size ratio, its
quality figures (stretch and angle distortion do not change under a similarity). The uv
layout of a chart is a property of the 2-D map alone, so a copy's charts are exactly as
bijective as the original's; only their distortion could differ, by the geometric mismatch
allowed (`MATCH_TOL`). Every copy still gets charts of its own in the atlas (its own texels):
the work of segmenting and solving is shared, not the texture.

Finding them is one pass over the pieces, without a Python loop over faces:

1. the pieces (vertex-connected: pieces share no vertex) and, per piece, its faces in input
   order with its vertices numbered by first appearance: two copies then have equal local
   face arrays;
2. pieces with equal local faces and equal similarity-invariant signatures (the distances of
   their first vertices from the centroid over the RMS radius, rounded) are candidates;
3. each candidate is aligned with the first of its group by the rotation that best maps one
   onto the other (Kabsch: the SVD of their 3 x 3 covariance, a proper rotation only) and is a
   copy when no vertex is further than `MATCH_TOL` RMS radii from its image.

A mesh of one piece, or of pieces that repeat nothing, is charted as before.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .mesh import connected_components

__all__ = [
    "MATCH_TOL",
    "Repeats",
    "candidates",
    "expand_labels",
    "find_repeats",
    "replicate",
    "similarity",
]

#: Largest distance of a copy's vertex from the original's image under the best similarity,
#: in RMS radii of the piece: copies made by moving a part (float32 exports: ~1e-7 of the
#: coordinates) match; a piece that differs anywhere by more is charted on its own. At this
#: tolerance a copy's stretch and angle distortion differ from the original's by ~1e-5.
MATCH_TOL = 1e-5
#: Vertices per piece whose distances from its centroid make the signature that groups
#: candidates before any alignment (2,000 random triangles: 2,000 groups of one, no SVD).
SIGNATURE_VERTICES = 8
#: Pieces of a group solved to choose from, at most: those its segmentation cut differently
#: (a symmetric part is cut by rounding); the one whose charts distort least is copied to the
#: others. 300 icospheres of 80 faces (``bench_atlas.py``'s spheres-300), cut and mapped one by
#: one: angle distortion 1.060-1.106 per sphere, 1.095 over the atlas; the first sphere's charts
#: copied to all: 1.099; the best of 3: 1.097; of 8: 1.087 (L2 1.0044 -> 1.0038).
CANDIDATES = 8
#: Rounding of the signature's distances (RMS radii): copies agree to rounding, and a pair that
#: falls on both sides of a rounding step is only a copy missed.
SIGNATURE_STEP = 1e-3


@dataclass(frozen=True)
class Repeats:
    """Groups of pieces of a mesh that are copies of one another (:func:`find_repeats`).

    Attributes
    ----------
    faces : tuple of (k_g, f_g) int64 ndarrays
        Per group, the faces of each of its ``k_g >= 2`` pieces, in corresponding order (row 0:
        the first piece's faces in input order).
    vertices : tuple of (k_g, n_g) int64 ndarrays
        Per group, the vertices of each piece, in corresponding order.
    scale : tuple of (k_g,) float64 ndarrays
        Per group, each piece's size over the first's.
    """

    faces: tuple
    vertices: tuple
    scale: tuple

    @property
    def n_pieces(self) -> int:
        return int(sum(len(f) for f in self.faces))


def similarity(P: np.ndarray, Q: np.ndarray) -> float | None:
    """``Q``'s size over ``P``'s when the points ``Q`` are the points ``P`` (row for row) moved
    by one rotation, uniform scale and translation to `MATCH_TOL` of their RMS radius, else
    None (also for a mirror image, or points all at one place)."""
    P = np.asarray(P, dtype=np.float64)
    Q = np.asarray(Q, dtype=np.float64)
    if P.shape != Q.shape or P.ndim != 2 or P.shape[1] != 3 or len(P) == 0:
        return None
    P, Q = P - P.mean(axis=0), Q - Q.mean(axis=0)
    rp, rq = np.sqrt((P**2).sum(axis=1).mean()), np.sqrt((Q**2).sum(axis=1).mean())
    if not (rp > 0 and rq > 0):
        return None
    return float(rq / rp) if _aligned(np.stack([P / rp, Q / rq])) else None


def find_repeats(V: np.ndarray, F: np.ndarray) -> Repeats | None:
    """The pieces of ``(V, F)`` that are copies of another piece (see the module's notes), or
    None when no piece is.

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray

    Returns
    -------
    Repeats or None
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    count, piece = connected_components(F, by="vertex")  # pieces share no vertex
    if count < 2:
        return None
    order = np.argsort(piece, kind="stable")  # faces piece by piece, input order within
    nf = np.bincount(piece, minlength=count)
    f_start = np.r_[0, np.cumsum(nf)]
    corners = F[order].ravel()
    # each vertex's first appearance in that order numbers it within its piece
    verts, first = np.unique(corners, return_index=True)
    verts = verts[np.argsort(first, kind="stable")]
    vpiece = piece[order][np.sort(first) // 3]
    nv = np.bincount(vpiece, minlength=count)
    v_start = np.r_[0, np.cumsum(nv)]
    local = np.empty(len(V), dtype=np.int64)
    local[verts] = np.arange(len(verts)) - v_start[vpiece]
    local_F = local[corners].reshape(-1, 3)

    groups = []
    # pieces of one size at a time: their local faces stacked, their signatures compared
    sizes = np.unique(np.c_[nf, nv], axis=0)
    for f_n, v_n in sizes:  # loop over piece sizes (a handful on a real model)
        members = np.flatnonzero((nf == f_n) & (nv == v_n))
        if len(members) < 2:
            continue
        fidx = f_start[members][:, None] + np.arange(f_n)
        topo = local_F[fidx].reshape(len(members), -1)
        vidx = v_start[members][:, None] + np.arange(v_n)
        P = V[verts[vidx]]  # (k, v_n, 3), vertices in first-appearance order
        centred = P - P.mean(axis=1, keepdims=True)
        radius = np.sqrt((centred**2).sum(axis=2).mean(axis=1))
        ok = radius > 0
        Q = centred / np.where(ok, radius, 1.0)[:, None, None]
        sig = np.round(np.linalg.norm(Q[:, :SIGNATURE_VERTICES], axis=2) / SIGNATURE_STEP).astype(
            np.int64
        )
        cls = _row_classes(np.c_[topo, sig][ok])[1]
        for c in np.flatnonzero(np.bincount(cls) >= 2):  # loop over candidate groups
            idx = np.flatnonzero(ok)[cls == c]
            for take in _aligned(Q[idx]):  # loop over its groups of copies
                take = idx[take]
                groups.append((fidx[take], vidx[take], radius[take] / radius[take[0]]))
    if not groups:
        return None
    return Repeats(
        faces=tuple(order[fi] for fi, _, _ in groups),
        vertices=tuple(verts[vi] for _, vi, _ in groups),
        scale=tuple(scale for _, _, scale in groups),
    )


def _row_classes(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The classes of equal rows of a 2-D integer array, as ``np.unique(a, axis=0,
    return_index=True, return_inverse=True)`` finds them but with each row compared as its
    bytes (a void view: 21 -> 6 ms on 300 rows of 248 numbers, where ``axis=0`` compares a
    structured type field by field): (each class's first row, each row's class)."""
    a = np.ascontiguousarray(a)
    rows = a.view(np.dtype((np.void, a.itemsize * a.shape[1]))).ravel()
    _, first, cls = np.unique(rows, return_index=True, return_inverse=True)
    return first, cls.ravel()


def _aligned(Q: np.ndarray) -> list[np.ndarray]:
    """Split candidates (normalized, centred vertices ``Q``, one row of points each) into
    groups of copies of their first member: the rows of each group of two or more, the
    original first. The first member left unmatched starts the next group (a loop that ends
    after one pass when the candidates are copies, as they are unless a signature collides)."""
    groups = []
    left = np.arange(len(Q))
    while len(left) >= 2:  # loop over groups within the candidates
        ref = Q[left[0]]
        # Kabsch: H = Q_k^T ref = U S W^T; R = U diag(1, 1, d) W^T takes Q_k onto ref, d = +-1
        # making it a rotation (a flat piece fits as well either way; a mirrored one then fails)
        H = np.einsum("kvi,vj->kij", Q[left], ref)
        U, _, Wt = np.linalg.svd(H)
        d = np.sign(np.linalg.det(U @ Wt))
        U[:, :, 2] *= d[:, None]
        R = U @ Wt
        err = np.abs(Q[left] @ R - ref[None]).max(axis=(1, 2))
        match = err <= MATCH_TOL
        match[0] = True
        if match.sum() >= 2:
            groups.append(left[match])
        left = left[~match]
    return groups


def candidates(labels: np.ndarray, repeats: Repeats, most: int = CANDIDATES) -> list:
    """Per group, the pieces worth solving: those whose segmentation (``labels``) cuts them
    differently from every piece before them, ``most`` at most (the first always). Copies can be
    cut differently: the segmentation's eigenvectors see each copy's rounding, and a symmetric
    part (a sphere) is cut by rounding alone; their charts then differ in quality (300
    icospheres: angle distortion 1.060-1.106 per sphere, median 1.097)."""
    out = []
    for faces in repeats.faces:  # loop over groups
        pattern = np.array([np.unique(labels[f], return_inverse=True)[1].ravel() for f in faces])
        out.append(np.sort(_row_classes(pattern)[0])[:most])
    return out


def expand_labels(labels: np.ndarray, repeats: Repeats, chosen: list) -> np.ndarray:
    """The segmentation ``labels`` with every piece of a group cut as its chosen piece
    (``chosen[g]``, a row of the group) is, by fresh labels (a chart per piece): compact,
    ``0 .. n - 1``. The chosen pieces keep their labels."""
    labels = labels.copy()
    fresh = int(labels.max()) + 1
    for faces, c in zip(repeats.faces, chosen, strict=True):  # loop over groups
        others = np.delete(faces, c, axis=0)
        own, rank = np.unique(labels[faces[c]], return_inverse=True)
        labels[others] = fresh + np.arange(len(others))[:, None] * len(own) + rank.ravel()
        fresh += len(others) * len(own)
    return np.unique(labels, return_inverse=True)[1].reshape(-1).astype(np.int64)


def replicate(
    charts: list, repeats: Repeats, chosen: list, n_faces: int, n_vertices: int, labels
) -> list:
    """The charts of the mesh: every chart of a group's chosen piece once more per other piece
    of the group (faces, vertices, uv scaled by the size ratio, quality and method as they
    are, ``source`` the piece's own label in ``labels``), the charts of no group as they are.
    ``charts`` hold the chosen pieces' and every piece's of no group (any other piece's are
    dropped), in mesh indices."""
    face_pos = np.full(n_faces, -1, dtype=np.int64)
    vert_pos = np.full(n_vertices, -1, dtype=np.int64)
    group_of = np.full(n_faces, -1, dtype=np.int64)
    row_of = np.full(n_faces, -1, dtype=np.int64)
    for g, (faces, verts) in enumerate(zip(repeats.faces, repeats.vertices, strict=True)):
        face_pos[faces] = np.arange(faces.shape[1])  # loop over groups: their index maps
        vert_pos[verts] = np.arange(verts.shape[1])
        group_of[faces] = g
        row_of[faces] = np.arange(len(faces))[:, None]
    out = []
    for c in charts:  # loop over charts: an original's, copied to the other pieces
        g = group_of[c.faces[0]]
        if g < 0:
            out.append(c)
            continue
        if row_of[c.faces[0]] != chosen[g]:
            continue  # a candidate not chosen: its piece gets the chosen one's charts
        faces, verts = repeats.faces[g], repeats.vertices[g]
        ratio = repeats.scale[g] / repeats.scale[g][chosen[g]]
        fp, vp = face_pos[c.faces], vert_pos[c.vertices]
        for j in range(len(faces)):  # loop over the group's pieces
            mine = faces[j, fp]
            out.append(
                c if j == chosen[g] else dataclasses.replace(
                    c, faces=mine, vertices=verts[j, vp], uv=c.uv * ratio[j],
                    source=int(labels[mine[0]]),
                )
            )  # fmt: skip
    return out
