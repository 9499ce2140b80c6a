"""segparam: triangle meshes to UV atlases with the Hessian-eigenfunction chart solver."""

from __future__ import annotations

__version__ = "0.1.0"

# The pictures' entry points at the top level (issue 18), imported on first use so that
# ``import segparam`` stays light (no numba kernels loaded until a picture is made).
_PICTURES = {
    "render_preview": "render",
    "write_viewer": "viewer",
    "write_flat_gifti": "flatmap",
    "render_flatmap": "flatmap",
}


def __getattr__(name: str):
    if name in _PICTURES:
        import importlib

        return getattr(importlib.import_module(f".{_PICTURES[name]}", __name__), name)
    raise AttributeError(f"module 'segparam' has no attribute {name!r}")
