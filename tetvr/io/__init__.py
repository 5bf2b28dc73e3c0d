"""Readers: mesh files through meshio (and the legacy VTK reader), ParaView collections
(.pvd, .vtm, .pvtu), and volume files (NRRD, MetaImage, NIfTI, DICOM, VTK). They make the
objects of :mod:`tetvr.mesh` and :mod:`tetvr.volume`; those objects never import a reader."""
