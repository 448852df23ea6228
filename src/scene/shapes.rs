//! Shapes -> triangles: quad, triangle, box, sierpinski, OBJ mesh, and their transforms.
