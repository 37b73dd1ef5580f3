"""Exports of a result that robot stacks load directly (MJCF, URDF, SDF, OBJ, GLB).

Per object (``ipr.export.model``): a smooth closed surface rebuilt from the result's 5 mm voxel
shape (``ipr.export.surface``), in an object frame at its centre of mass with the world's
axes; its pose; its mass and inertia at a uniform density; convex collision pieces. The scene
(``ipr.export.placement``): the support plane and the objects' start poses, separated where
the rounding made them interpenetrate.
"""
