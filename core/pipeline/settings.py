"""Solver settings (DESIGN.md section 3) and the named presets of the speed / accuracy trade-off."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from ..errors import VisradError
from ..hierarchy import GridSettings

#: Accurate is the 1999 paper's mode (exact form factors, 2 % JND); Fast its ray-cast alternative with a
#: coarser threshold and fewer iterations.
PRESETS = {
    "accurate": {"jnd": 0.02, "max_iterations": 10, "form_factors": "exact", "discontinuities": True},
    "fast": {"jnd": 0.05, "max_iterations": 4, "form_factors": 16, "discontinuities": False},
}


@dataclass(frozen=True)
class Settings:
    """What the solver does.

    jnd: just noticeable difference epsilon_percep (seed 000 section 6.1), a fraction of the display's
        maximum luminance after Ward's tone mapping; refinement stops where the error it would remove is below.
    max_iterations: most refinement iterations (subdivide, refine links, gather) of `Solver.solve`.
    max_bounces: None = full global illumination (the linear system solved exactly), k >= 1 = k bounces
        (1 = direct light only: B = E + rho sum E_l F_l).
    form_factors: 'exact' (occluded point-to-polygon form factors from exact views) or a positive int, the
        number of jittered rays per form factor (seed 000 Table 1).
    regular_levels: refinement iterations that subdivide with a regular grid (section 6.2); later ones insert
        the ranked discontinuities.
    discontinuities: build the Visibility Skeleton for the emitters and insert their ranked visual events
        (sections 5 and 6.4) from iteration regular_levels + 1 on; False refines at the worst samples only.
    source_refinement: with exact form factors, links whose source is too uneven for its average are split into
        exact links to elements of the source's hierarchy (sources.py). Off by default: each refined link
        becomes one link per element of the source's first grid level (hundreds), and at vertices against
        touching objects it moves the energy balance by about 1 %, until the source tree has coarser levels.
    display_max_luminance: L_dmax of Ward's operator in cd/m^2; luminous_efficacy: lm/W turning our W/m^2
        into photometric units (179 lm/W, the white-light efficacy Ward's Radiance uses).
    grid: the regular subdivision's spacing; seed: the jittered rays' seed.
    """

    jnd: float = 0.02
    max_iterations: int = 10
    max_bounces: int | None = None
    form_factors: str | int = "exact"
    regular_levels: int = 2
    discontinuities: bool = True
    source_refinement: bool = False
    display_max_luminance: float = 100.0
    luminous_efficacy: float = 179.0
    grid: GridSettings = field(default_factory=GridSettings)
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 < self.jnd < 1.0:
            raise VisradError(f"Settings.jnd must lie in (0, 1), got {self.jnd!r}")
        if isinstance(self.max_iterations, bool) or not isinstance(self.max_iterations, int) or self.max_iterations < 0:
            raise VisradError(f"Settings.max_iterations must be an integer >= 0, got {self.max_iterations!r}")
        bounces = self.max_bounces
        if bounces is not None and (isinstance(bounces, bool) or not isinstance(bounces, int) or bounces < 1):
            raise VisradError(f"Settings.max_bounces must be None (full) or an integer >= 1, got {bounces!r}")
        rays = self.form_factors
        if rays != "exact" and (isinstance(rays, bool) or not isinstance(rays, int) or rays < 1):
            raise VisradError(f"Settings.form_factors must be 'exact' or a positive ray count, got {rays!r}")
        if isinstance(self.regular_levels, bool) or not isinstance(self.regular_levels, int) or self.regular_levels < 0:
            raise VisradError(f"Settings.regular_levels must be an integer >= 0, got {self.regular_levels!r}")
        if not isinstance(self.discontinuities, bool):
            raise VisradError(f"Settings.discontinuities must be True or False, got {self.discontinuities!r}")
        if not isinstance(self.source_refinement, bool):
            raise VisradError(f"Settings.source_refinement must be True or False, got {self.source_refinement!r}")
        if not self.display_max_luminance > 0.0 or not self.luminous_efficacy > 0.0:
            raise VisradError("Settings.display_max_luminance and luminous_efficacy must be positive")

    @staticmethod
    def preset(name: str, **overrides) -> Settings:
        """The settings of preset `name` ('accurate' or 'fast'), with keyword overrides."""
        key = str(name).lower()
        if key not in PRESETS:
            raise VisradError(f"unknown preset {name!r}; presets: {', '.join(sorted(PRESETS))}")
        return replace(Settings(**PRESETS[key]), **overrides)

    @property
    def exact(self) -> bool:
        return self.form_factors == "exact"
