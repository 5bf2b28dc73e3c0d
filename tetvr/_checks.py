"""Argument checks shared by the public entry points."""

from __future__ import annotations

__all__ = ["check_instances"]


def check_instances(**named: tuple[object, type]) -> None:
    """Raise ``TypeError("NAME must be a CLS, got TYPE")`` for the first argument that is
    not an instance of its class, e.g. ``check_instances(camera=(camera, Camera))``."""
    for name, (value, cls) in named.items():
        if not isinstance(value, cls):
            raise TypeError(f"{name} must be a {cls.__name__}, got {type(value).__name__}")
