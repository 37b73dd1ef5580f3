"""Geometry shared by every stage, below perception: world points of depth images and plane
fits (``kernels``, ``planes``). Imports nothing from ipr but ``ipr.camera``."""
