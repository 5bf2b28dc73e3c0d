"""What to draw, as files and examples: the scene JSON, ParaView states, the bundled examples
and the stability cases. Above the facade: a scene renders through :func:`tetvr.render`."""
