"""The calls users bring from xatlas-python and trimesh.

:func:`parametrize` has xatlas-python's contract (``xatlas.parametrize(V, F)``), so code written
for it runs unchanged with ``segparam.parametrize(V, F)``; :func:`unwrap` is
``trimesh.Trimesh.unwrap`` with segparam's charts; :func:`atlas_to_trimesh` (also
:meth:`segparam.pipeline.Atlas.to_trimesh`) gives an atlas as a textured trimesh mesh.

xatlas-python 0.0.11, measured on its own output: ``vmapping`` (k,) uint32, ``indices`` (m, 3)
uint32 in the input's face order, ``uvs`` (k, 2) float32, all C-contiguous; positions and
faces given as lists, float32/float64 and any integer dtype are accepted. Faces it cannot
chart (a repeated index, zero area) stay in ``indices`` at their place, on output vertices of
their own whose uv is (0, 0); unreferenced input vertices are not in ``vmapping``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import ConfigError, InvalidMeshError
from .mesh import check_mesh, mesh_arrays

if TYPE_CHECKING:  # pragma: no cover
    import trimesh

    from .pipeline import Atlas, PipelineConfig

__all__ = ["atlas_to_trimesh", "parametrize", "unwrap", "xatlas_arrays"]

#: uv of the corners of faces the pipeline removed (degenerate, duplicate): xatlas's choice for
#: the faces it cannot chart, so that code checking ``uvs`` in the unit square still holds.
DROPPED_UV = (0.0, 0.0)


def _keep_vertices(config: PipelineConfig | None) -> PipelineConfig:
    """``config`` with remeshing off: the atlas must be on the caller's own vertices."""
    from .pipeline import PipelineConfig

    cfg = PipelineConfig() if config is None else config
    if not isinstance(cfg, PipelineConfig):
        raise ConfigError(f"config must be a PipelineConfig, got {type(cfg).__name__}")
    if cfg.remesh.mode == "on":
        raise ConfigError(
            "parametrize keeps the input vertices (xatlas's contract), so [remesh] mode 'on' "
            "cannot apply; use build_atlas to remesh"
        )
    if cfg.remesh.mode != "off":  # "auto" (the default): never remesh here
        cfg = cfg.replace(remesh={"mode": "off"})
    return cfg


def parametrize(
    V: Any,
    F: Any = None,
    *,
    config: PipelineConfig | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chart and pack a mesh on its own vertices, with xatlas-python's contract.

    ``vmapping, indices, uvs = segparam.parametrize(V, F)`` where ``xatlas.parametrize(V, F)``
    was: the mesh is split along the seams only (no remeshing), and
    ``V[vmapping][indices]`` equals ``V[F]`` exactly, face by face and corner by corner.

    Parameters
    ----------
    V : (n, 3) array_like of float (float32 or float64), or a trimesh.Trimesh (then no F)
    F : (m, 3) array_like of int (any integer dtype)
    config : PipelineConfig, optional
        Every stage's options; its remesh mode is taken as ``"off"`` (``"auto"`` is the
        default and is turned off here; ``"on"`` is refused).
    seed : int

    Returns
    -------
    vmapping : (k,) uint32 ndarray
        The input vertex of each output vertex (one per input vertex and chart it is in).
    indices : (m, 3) uint32 ndarray
        Every input face, in the input's order and corner order, indexing the output vertices.
    uvs : (k, 2) float32 ndarray
        Atlas coordinates in ``[0, 1]^2``, charts ``config.pack.padding`` texels apart.

    Notes
    -----
    As xatlas does, faces that cannot be charted stay in ``indices`` on output vertices of
    their own with uv ``(0, 0)`` (:data:`DROPPED_UV`): here the faces that
    :func:`segparam.clean.clean` removes (a repeated vertex, zero area, a duplicate of an
    earlier face; ``build_atlas(V, F).cleaning.removed_faces`` lists them with the reason).
    Input vertices closer than the clean stage's merge tolerance share a chart position but
    keep their own output vertices. A face that cleaning had to turn (inconsistent winding)
    keeps its input corner order, so its uv triangle is mirrored. Unreferenced input vertices
    are not in ``vmapping``. Unlike xatlas, a mesh whose every face is degenerate is an
    :class:`~segparam.errors.InvalidMeshError`.

    Raises
    ------
    InvalidMeshError
        A malformed mesh (shape, NaN, index out of range, no face left after cleaning).
    ConfigError
        A bad option or seed, or remesh mode ``"on"``.
    """
    from .pipeline import build_atlas

    V, F = check_mesh(*mesh_arrays(V, F), allow_degenerate=True)
    atlas = build_atlas(V, F, _keep_vertices(config), seed=seed)
    return xatlas_arrays(atlas, V, F)


def xatlas_arrays(atlas: Atlas, V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(vmapping, indices, uvs)`` of an atlas built without remeshing from ``V, F``.

    Each output vertex is one (input vertex, atlas uv row) pair met at a corner of a kept
    face; the corners of removed faces get one output vertex per input vertex, at
    :data:`DROPPED_UV`. Which cleaned corner holds which input corner is found by position
    (cleaning may merge near vertices and reverse a face's winding; the three corners of a kept
    face are distinct points, so the nearest one is the right one).
    """
    cleaning = atlas.cleaning
    if cleaning is None or atlas.remeshing is None or atlas.remeshing.remeshed:
        raise InvalidMeshError("xatlas arrays need an atlas built from V, F without remeshing")
    kept, removed = cleaning.face_index, cleaning.removed_faces
    Fin = F[kept]  # (m', 3) input corners of the kept faces
    P = atlas.V[atlas.F]  # (m', 3, 3) cleaned corner positions
    gap = np.linalg.norm(V[Fin][:, :, None, :] - P[:, None, :, :], axis=3)  # input x cleaned
    corner = gap.argmin(axis=2)  # (m', 3) cleaned corner of each input corner
    uv_row = np.take_along_axis(atlas.uv_F, corner, axis=1)

    n_uv = len(atlas.uv)
    key = Fin.ravel() * n_uv + uv_row.ravel()
    pairs, inverse = np.unique(key, return_inverse=True)
    vertex = pairs // n_uv
    uv = atlas.uv[pairs % n_uv]

    dropped, dropped_inverse = np.unique(F[removed].ravel(), return_inverse=True)
    vmapping = np.concatenate([vertex, dropped]).astype(np.uint32)
    uvs = np.concatenate([uv, np.tile(DROPPED_UV, (len(dropped), 1))]).astype(np.float32)
    indices = np.empty(F.shape, dtype=np.uint32)
    indices[kept] = inverse.reshape(-1, 3)
    indices[removed] = len(pairs) + dropped_inverse.reshape(-1, 3)
    return vmapping, indices, uvs


def unwrap(
    mesh: trimesh.Trimesh,
    image: Any = None,
    *,
    config: PipelineConfig | None = None,
    seed: int = 0,
) -> trimesh.Trimesh:
    """``mesh.unwrap(image)`` with segparam's atlas in place of xatlas's.

    As ``trimesh.Trimesh.unwrap`` does: a new ``Trimesh`` (``process=False``) whose vertices
    are ``mesh.vertices[vmapping]``, faces ``indices`` and visual
    ``TextureVisuals(uv=uvs, image=image)``, from :func:`parametrize`; ``mesh`` is unchanged.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    image : PIL.Image.Image, optional
        The material's texture, as in trimesh.
    config, seed
        As in :func:`parametrize`.

    Raises
    ------
    InvalidMeshError
        ``mesh`` is not a ``trimesh.Trimesh``, or as in :func:`parametrize`.
    """
    import trimesh
    from trimesh.visual import TextureVisuals

    if not isinstance(mesh, trimesh.Trimesh):
        raise InvalidMeshError(f"unwrap takes a trimesh.Trimesh, got {type(mesh).__name__}")
    vmapping, indices, uvs = parametrize(mesh, config=config, seed=seed)
    return trimesh.Trimesh(
        vertices=np.asarray(mesh.vertices)[vmapping],
        faces=indices,
        visual=TextureVisuals(uv=uvs, image=image),
        process=False,
    )


def atlas_to_trimesh(atlas: Atlas, image: Any = None) -> trimesh.Trimesh:
    """The atlas as a ``trimesh.Trimesh`` with ``TextureVisuals``: vertices split along the
    seams (one per uv row: ``atlas.V[atlas.uv_vertex]``), faces ``atlas.uv_F``, uv
    ``atlas.uv`` and the checker texture of the OBJ/GLB outputs unless ``image`` is given."""
    import trimesh
    from trimesh.visual import TextureVisuals

    from .export import checker_image, checker_size

    texture = checker_image(checker_size(atlas.packing.size)) if image is None else image
    return trimesh.Trimesh(
        vertices=atlas.V[atlas.uv_vertex],
        faces=atlas.uv_F,
        visual=TextureVisuals(uv=atlas.uv, image=texture),
        process=False,
    )
