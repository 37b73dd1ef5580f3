"""Geometry shared by every stage, below perception: world points of depth images, plane fits
and convex hulls (``kernels``, ``planes``, ``convex``). Imports nothing from ipr but
``ipr_shapes.camera``."""
