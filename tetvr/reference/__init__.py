"""The exact CPU renderers every image is measured against: tet meshes
(:mod:`~tetvr.reference.tets`, which runs :mod:`~tetvr.reference.segments` and
:mod:`~tetvr.reference.integrate`) and volumes (:mod:`~tetvr.reference.volume`). No OpenGL."""
