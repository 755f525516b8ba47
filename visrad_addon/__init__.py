"""VisRad Blender layer: converts Blender scenes to core.Scene and writes results back (issue 6).

Nothing is registered yet; the engine in core/ is usable on its own.
"""


def register():
    pass


def unregister():
    pass
