"""Geometry shared by every layer: rigid transforms, voxel thinning, normals (no I/O)."""
