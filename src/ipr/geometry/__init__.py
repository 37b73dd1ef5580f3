"""Geometry below every stage: plane fits, convex hulls and the compiled loops they need."""
