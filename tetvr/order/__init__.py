"""What a frame draws and in which order, decided on the CPU: culling, the visibility sort
(MPVONC, XMPVO), the method choice (projected tetrahedra or tet marching) and whether float32
resolves the view."""
