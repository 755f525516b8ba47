"""visrad core: the Blender-independent radiosity engine.

Implements the seed papers (shared/seeds/README.md): the validated polygon scene and exact point-to-polygon
views and form factors (Durand et al. 1999, sections 2 and 4.2.1), ray casting for occlusion and jittered
form factors, the Visibility Skeleton (Durand et al. 1997), hierarchical triangulations with lazy-wavelet
push-pull (1999, section 3) and the visibility-driven hierarchical radiosity solver (1999, sections 4-6).

Never imports bpy or mathutils; all imports inside core are relative so that `import core` works from the
repository root and `from ..core import ...` works inside the Blender extension.
"""
