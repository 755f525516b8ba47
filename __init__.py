"""Blender extension entry point: Blender loads the package root, the add-on lives in visrad_addon.

The imports happen inside register/unregister so that this file can also be imported on its own (pytest
imports a rootdir __init__.py as a plain module when the checkout's folder name is not a package name).
"""


def register():
    from .visrad_addon import register as register_addon

    register_addon()


def unregister():
    from .visrad_addon import unregister as unregister_addon

    unregister_addon()
