"""Sample meshes shipped with segparam (see README.md in this folder)."""
