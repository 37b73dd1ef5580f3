"""Perception: from RGB-D frames to partial objects, facets and free space (paper Sec. III)."""
