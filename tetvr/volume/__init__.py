"""CT/MR volumes: :class:`~tetvr.volume.volume.Volume`, a regular grid of samples with its
placement in world space. Reading volume files is :mod:`tetvr.io`."""
