"""The acceleration layer: where a lane's segment meets the surface, found fast.

- `start_points`: the first crossing of the segment P-L (the walk's `M0`);
- `face_cells`: binned face cells for irregular meshes;
- `bvh`: a bounding-volume hierarchy of faces;
- `cones`: refraction cones that cull the faces a lane cannot use;
- `occlusion`: shadow tests of found paths;
- `prepared`: a mesh with its acceleration structures, built once per mesh.
"""
