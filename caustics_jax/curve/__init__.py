"""The curve layer: the coplanarity conic inside a triangle as arcs, and the roots of the
signed sine along them.

- `arcs`: arcs of the conic between edge crossings, the next crossing along a tangent;
- `arc_roots`: certified roots of the objective on each arc (the exhaustive reference).
"""
