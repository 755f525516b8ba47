"""The Visibility Skeleton (Durand, Drettakis & Puech, SIGGRAPH 97; seed 003) as extended by seed 000 section 2.

Exact global visibility for a polygon scene as a graph: nodes are extremal stabbing lines (VV, VEE, EVE, E4,
and lines in a face plane), arcs are the critical line swaths between them (EV, EEE). Built from candidate
lines (`enumeration`, sections 3.2.1-3.2.2) cast through the scene (`validation`, sections 3.2-3.3 and
appendix 7.2), assembled into arcs (`graph`, section 3.3), stored per polygon and per vertex and queried
(`skeleton`, sections 3.1, 4 and 5): exact vertex views and form factors, discontinuity meshes, exact blocker
lists, interactions; lazily for chosen sources.

    from core.skeleton import build_skeleton
    skel = build_skeleton(scene, sources=None)        # or sources=[light ids]: lazy, extended on demand
    skel.form_factor(vertex, source, receiver); skel.visible_boundary(vertex, source)
    skel.discontinuities(source, receiver); skel.blockers(source, receiver); skel.interactions(polygon)
    skel.stats
"""

from .skeleton import Skeleton, build_skeleton

__all__ = ["Skeleton", "build_skeleton"]
