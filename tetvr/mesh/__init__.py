"""The tetrahedral mesh and what is computed from it alone: :class:`~tetvr.mesh.tetmesh.TetMesh`,
cells split into tets, face adjacency, the ray caster's per-tet records, synthetic meshes, and
meshes made from surfaces. Reads no files (that is :mod:`tetvr.io`)."""
