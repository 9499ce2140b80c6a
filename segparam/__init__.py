"""segparam: triangle meshes to UV atlases with the Hessian-eigenfunction chart solver."""

from __future__ import annotations

__version__ = "0.1.0"
