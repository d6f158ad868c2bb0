"""The method: slices, NDT grids, kernels, optimisers, the staged registration, ICP refinement.

``register`` (file paths or arrays) and ``register_prepared`` (prepared scans) are the entry
points; every stage is public in its own module.
"""
