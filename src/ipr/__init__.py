"""ipr: complete 3D models of unknown rigid objects in clutter by inverse physics reasoning.

The method is Song & Boularias, "Inferring 3D Shapes of Unknown Rigid Objects in Clutter through
Inverse Physics Reasoning", RA-L 2018. Units are metres and radians; the world frame is z-up with
gravity along -z. Millimetres appear only at the BOP file boundary.

Importing ipr (or any of its modules) leaves the process's environment alone: the offscreen
OpenGL backend is chosen only where ipr renders (``ipr.gl``).
"""

#: The version; pyproject.toml reads it from here.
__version__ = "0.1.0"
#: The distribution's name on the package index (``pip install ipr-shapes``); the import package
#: and the command are ``ipr`` (docs/DESIGN_NOTES.md, "Distribution name").
DISTRIBUTION = "ipr-shapes"
