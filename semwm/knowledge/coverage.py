"""Where detectors see: the volumes clutter and new objects are spread over (``mht``)."""

from __future__ import annotations

import math

from semwm.knowledge.model import DetectorSpec, WorldSettings


def region_volume(world: WorldSettings) -> float | None:
    """The region's area (2D, m^2) or volume (3D, m^3); ``None`` without a region."""
    if world.region is None:
        return None
    return math.prod(high - low for low, high in world.region)


def coverage_volume(detector: DetectorSpec, world: WorldSettings) -> float | None:
    """The volume a detector's clutter is spread over: its coverage (``range`` and
    ``field_of_view``: a disc sector in 2D, a cone in 3D) or the region, whichever is
    smaller; ``None`` when neither is known."""
    region = region_volume(world)
    if detector.range is None:
        return region
    fov = detector.field_of_view or 360.0
    if world.dimension == 2:
        own = math.pi * detector.range**2 * fov / 360.0
    else:  # a cone of opening angle fov: solid angle 2 pi (1 - cos(fov / 2))
        own = 2.0 * math.pi * (1.0 - math.cos(math.radians(fov) / 2.0)) / 3.0 * detector.range**3
    return own if region is None else min(own, region)


def birth_volume(world: WorldSettings, detectors: tuple[DetectorSpec, ...]) -> float | None:
    """The volume new objects are spread over: the region, else the largest coverage."""
    region = region_volume(world)
    if region is not None:
        return region
    volumes = [v for d in detectors if (v := coverage_volume(d, world)) is not None]
    return max(volumes, default=None)
