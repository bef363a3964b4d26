"""The math layer: per-sample formulas with no mesh or scheduling in them.

- `geometry`: refraction, reflection, Fresnel (seed 002 eq. 3.1-3.2);
- `barycentric`: points, edges and interpolated normals of a triangle;
- `conic`: the coplanarity conic's coefficients, tangent and edge roots (seed 001 eq. 1-15);
- `objectives`: the signed sine and the Newton residuals (seed 001 eq. 16-24);
- `crossing`: segment/triangle crossings (start points, visibility).
"""
