"""The radiosity pipeline: visibility-driven hierarchical radiosity end to end (seed 000 Fig. 7).

Implements seed 000 section 4 (point-polygon links with exact form factors, gathering at vertices, push-pull
over the hierarchical triangulations), section 6.1 (Ward's tone mapping and the 2 % just noticeable
difference), 6.2 (regular then feature-driven subdivision), 6.3 (maxima of important transfers) and 6.4 (the
radiometric oracle), with the DESIGN.md section 3 API: Settings, Solver (stages build_skeleton,
coarse_lighting, refine, solve) and Result (radiosity_at).
"""

from .result import Result
from .settings import PRESETS, Settings
from .solver import Solver

__all__ = ["PRESETS", "Result", "Settings", "Solver"]
