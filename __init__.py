"""Blender extension entry point: Blender loads the package root, the add-on lives in visrad_addon."""

from .visrad_addon import register, unregister

__all__ = ["register", "unregister"]
