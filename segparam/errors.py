"""The one exception hierarchy of segparam.

Every error that a user can cause (a bad file, a mesh the solver cannot take, a bad option) is a
`SegparamError`; the CLI turns it into one line on stderr and exit code 2.
"""

from __future__ import annotations


class SegparamError(Exception):
    """Base class of every error segparam raises on purpose."""


class InvalidMeshError(SegparamError, ValueError):
    """The mesh is not what the called function needs (shape, indices, topology, size)."""


class MeshFileError(SegparamError, OSError):
    """A mesh file cannot be read (missing, unreadable, unsupported format, not a mesh)."""


class ConfigError(SegparamError, ValueError):
    """A configuration value or file is invalid (unknown key, out-of-range value)."""


class SolverError(SegparamError, RuntimeError):
    """A numerical stage failed in a way the input did not predict (e.g. no convergence)."""
