"""Perceptual thresholds (seed 000 section 6.1): Ward's contrast-preserving scale factor with a static
adaptation level, the average radiosity of the scene's polygons, and the just noticeable difference.

A radiosity difference dB (W/m^2, RGB) is perceptible when sf x L(dB) exceeds jnd, where L is luminance in
cd/m^2 (Rec. 709 luminance of B / pi times the luminous efficacy) and sf = 1/L_dmax [(1.219 + (L_dmax/2)^0.4) /
(1.219 + L_wa^0.4)]^2.5 maps world luminance to a fraction of the display's maximum.
"""

from __future__ import annotations

import math

import numpy as np

LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


def luminance(radiosity: np.ndarray, efficacy: float) -> np.ndarray:
    """Luminance in cd/m^2 of radiosities (..., 3) W/m^2: efficacy x Y(B) / pi."""
    return efficacy * (np.asarray(radiosity, dtype=np.float64) @ LUMINANCE_WEIGHTS) / math.pi


def ward_scale_factor(world_adaptation: float, display_max: float) -> float:
    """Ward's sf (display fraction per cd/m^2) for world adaptation luminance L_wa and display maximum L_dmax."""
    adaptation = max(float(world_adaptation), 0.0)
    ratio = (1.219 + (display_max / 2.0) ** 0.4) / (1.219 + adaptation**0.4)
    return ratio**2.5 / display_max


def radiosity_threshold(average_radiosity: np.ndarray, settings) -> float:
    """The smallest perceptible luminance-weighted radiosity difference, W/m^2 (Y of an RGB difference).

    average_radiosity (3,): the area-weighted average radiosity of the scene's polygons (static adaptation).
    """
    adaptation = float(luminance(average_radiosity, settings.luminous_efficacy))
    sf = ward_scale_factor(adaptation, settings.display_max_luminance)
    return settings.jnd * math.pi / (sf * settings.luminous_efficacy)


def perceptible(difference: np.ndarray, threshold: float) -> np.ndarray:
    """True where the luminance of |difference| (..., 3) W/m^2 reaches the threshold of radiosity_threshold."""
    return np.abs(np.asarray(difference, dtype=np.float64)) @ LUMINANCE_WEIGHTS >= threshold
