"""segparam: triangle meshes to UV atlases with the Hessian-eigenfunction chart solver.

The public API is reachable from the package, loaded lazily (PEP 562): ``import segparam`` reads
this file only, and ``segparam.build_atlas`` imports :mod:`segparam.pipeline` (numpy, scipy,
numba ...) the first time it is used. Type checkers see the names through the
``TYPE_CHECKING`` block below.

Five functions share their name with their module: ``segparam.bake``, ``segparam.clean``,
``segparam.remesh``, ``segparam.segment`` and ``segparam.repack`` are the modules (call
``segparam.clean.clean(V, F)``, ``segparam.bake.bake(...)``). A package attribute named like a
submodule is replaced by the module as soon as anything imports the submodule, so exporting the
functions under those names would make ``segparam.clean`` a function or a module depending on
import order.
"""

__version__ = "0.1.0"

# Where each public name lives (the module is imported on first access).
_EXPORTS = {
    # xatlas / trimesh face
    "parametrize": "interop",
    "unwrap": "interop",
    # whole pipeline
    "build_atlas": "pipeline",
    "build_atlases": "pipeline",
    "MultiAtlas": "pipeline",
    "pack_atlas": "pipeline",
    "Atlas": "pipeline",
    "PipelineConfig": "pipeline",
    "load_config": "pipeline",
    "config_from_dict": "pipeline",
    # files
    "load_mesh": "io",
    "save_atlas": "export",
    # stages, their configs and results
    "CleanResult": "clean",
    "RemeshConfig": "remesh",
    "RemeshResult": "remesh",
    "SegmentConfig": "segment",
    "Segmentation": "segment",
    "parameterize_charts": "split",
    "SplitConfig": "split",
    "ChartSet": "split",
    "parameterize_chart": "parameterize",
    "HessianSolver": "parameterize",
    "ChartMap": "parameterize",
    "pack_charts": "pack",
    "PackConfig": "pack",
    "PackResult": "pack",
    # pictures and data on the atlas
    "render_preview": "render",
    "write_viewer": "viewer",
    "write_flat_gifti": "flatmap",
    "render_flatmap": "flatmap",
    # existing uv islands
    "uv_islands": "repack",
    "RepackConfig": "repack",
    "RepackResult": "repack",
    # errors
    "SegparamError": "errors",
    "InvalidMeshError": "errors",
    "MeshFileError": "errors",
    "ConfigError": "errors",
    "SolverError": "errors",
}

# The modules whose main function has the module's name (see the module docstring).
_SAME_NAME_MODULES = ("bake", "clean", "remesh", "repack", "segment")

# Written out so that tools read it (tests/test_face.py checks it against the two above).
__all__ = [
    "Atlas",
    "ChartMap",
    "ChartSet",
    "CleanResult",
    "ConfigError",
    "HessianSolver",
    "InvalidMeshError",
    "MeshFileError",
    "MultiAtlas",
    "PackConfig",
    "PackResult",
    "PipelineConfig",
    "RemeshConfig",
    "RemeshResult",
    "RepackConfig",
    "RepackResult",
    "SegmentConfig",
    "Segmentation",
    "SegparamError",
    "SolverError",
    "SplitConfig",
    "__version__",
    "bake",
    "build_atlas",
    "build_atlases",
    "clean",
    "config_from_dict",
    "load_config",
    "load_mesh",
    "pack_atlas",
    "pack_charts",
    "parameterize_chart",
    "parameterize_charts",
    "parametrize",
    "remesh",
    "render_flatmap",
    "render_preview",
    "repack",
    "save_atlas",
    "segment",
    "unwrap",
    "uv_islands",
    "write_flat_gifti",
    "write_viewer",
]


def __getattr__(name: str) -> object:
    """Import the module that holds ``name`` on first access (PEP 562)."""
    import importlib

    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value  # later lookups skip this function
        return value
    if name in _SAME_NAME_MODULES:
        return importlib.import_module(f".{name}", __name__)  # binds the attribute itself
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing (type checkers know it)
if TYPE_CHECKING:  # pragma: no cover
    from . import bake, clean, remesh, repack, segment
    from .clean import CleanResult
    from .errors import ConfigError, InvalidMeshError, MeshFileError, SegparamError, SolverError
    from .export import save_atlas
    from .flatmap import render_flatmap, write_flat_gifti
    from .interop import parametrize, unwrap
    from .io import load_mesh
    from .pack import PackConfig, PackResult, pack_charts
    from .parameterize import ChartMap, HessianSolver, parameterize_chart
    from .pipeline import (
        Atlas,
        MultiAtlas,
        PipelineConfig,
        build_atlas,
        build_atlases,
        config_from_dict,
        load_config,
        pack_atlas,
    )
    from .remesh import RemeshConfig, RemeshResult
    from .render import render_preview
    from .repack import RepackConfig, RepackResult, uv_islands
    from .segment import Segmentation, SegmentConfig
    from .split import ChartSet, SplitConfig, parameterize_charts
    from .viewer import write_viewer
