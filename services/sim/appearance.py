"""What things look like and weigh: colours, artifact sizes and masses, lights, per seed.

Every draw comes from the caller's `numpy.random.Generator`, as a Python float (msgspec
encodes no numpy scalars). Palettes are plausible industrial colours; each drawn colour is
jittered a little so that no two seeds look alike.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from common.messages.world import ArtifactClass, Cuboid, Cylinder, Hall, Light, Lighting, Rgba

WALL_COLOURS: tuple[Rgba, ...] = (
    (0.78, 0.78, 0.76, 1.0),
    (0.82, 0.78, 0.68, 1.0),
    (0.70, 0.76, 0.80, 1.0),
    (0.85, 0.85, 0.85, 1.0),
)
RACK_COLOURS: tuple[Rgba, ...] = (
    (0.10, 0.30, 0.65, 1.0),
    (0.90, 0.45, 0.10, 1.0),
    (0.35, 0.38, 0.40, 1.0),
)
BENCH_COLOURS: tuple[Rgba, ...] = (
    (0.55, 0.40, 0.25, 1.0),
    (0.45, 0.47, 0.50, 1.0),
    (0.20, 0.35, 0.30, 1.0),
)
TABLE_COLOURS: tuple[Rgba, ...] = (
    (0.92, 0.92, 0.90, 1.0),
    (0.65, 0.50, 0.35, 1.0),
    (0.30, 0.32, 0.35, 1.0),
    (0.75, 0.80, 0.85, 1.0),
)
MACHINE_COLOURS: tuple[Rgba, ...] = (
    (0.85, 0.75, 0.10, 1.0),
    (0.25, 0.50, 0.30, 1.0),
    (0.60, 0.62, 0.65, 1.0),
    (0.70, 0.20, 0.15, 1.0),
)
PALLET_COLOURS: tuple[Rgba, ...] = (
    (0.72, 0.58, 0.38, 1.0),
    (0.60, 0.45, 0.28, 1.0),
    (0.80, 0.70, 0.50, 1.0),
)


BOTTLE_COLOURS: tuple[Rgba, ...] = (
    (0.10, 0.45, 0.15, 1.0),
    (0.20, 0.45, 0.85, 1.0),
    (0.45, 0.25, 0.10, 1.0),
    (0.90, 0.90, 0.92, 1.0),
    (0.80, 0.10, 0.10, 1.0),
)
CAN_COLOURS: tuple[Rgba, ...] = (
    (0.85, 0.05, 0.05, 1.0),
    (0.75, 0.76, 0.78, 1.0),
    (0.10, 0.20, 0.70, 1.0),
    (0.95, 0.80, 0.10, 1.0),
)
BOX_COLOURS: tuple[Rgba, ...] = (
    (0.70, 0.55, 0.35, 1.0),
    (0.95, 0.95, 0.92, 1.0),
    (0.20, 0.60, 0.70, 1.0),
    (0.90, 0.40, 0.10, 1.0),
)
SHIRT_COLOURS: tuple[Rgba, ...] = (
    (1.00, 0.50, 0.05, 1.0),
    (0.90, 0.95, 0.10, 1.0),
    (0.15, 0.25, 0.55, 1.0),
    (0.45, 0.45, 0.47, 1.0),
    (0.15, 0.45, 0.20, 1.0),
    (0.65, 0.10, 0.10, 1.0),
)
TROUSERS_COLOURS: tuple[Rgba, ...] = (
    (0.10, 0.12, 0.25, 1.0),
    (0.08, 0.08, 0.08, 1.0),
    (0.35, 0.35, 0.35, 1.0),
    (0.55, 0.50, 0.35, 1.0),
)
SKIN_COLOURS: tuple[Rgba, ...] = (
    (0.96, 0.80, 0.69, 1.0),
    (0.87, 0.67, 0.52, 1.0),
    (0.65, 0.45, 0.30, 1.0),
    (0.40, 0.27, 0.18, 1.0),
)


def uniform(rng: np.random.Generator, low: float = 0.0, high: float = 1.0) -> float:
    """One uniform draw as a Python float (msgspec encodes no numpy scalars)."""
    return float(rng.uniform(low, high))


def colour(rng: np.random.Generator, palette: Sequence[Rgba], jitter: float = 0.04) -> Rgba:
    """A palette colour, each channel moved by up to `jitter`."""
    base = np.array(palette[int(rng.integers(len(palette)))][:3])
    r, g, b = np.clip(base + rng.uniform(-jitter, jitter, 3), 0.0, 1.0)
    return (float(r), float(g), float(b), 1.0)


def artifact_body(
    rng: np.random.Generator, cls: ArtifactClass
) -> tuple[Cylinder | Cuboid, float, Rgba]:
    """Shape, mass (kg) and colour of one artifact of a class."""
    if cls == "bottle":
        shape: Cylinder | Cuboid = Cylinder(uniform(rng, 0.02, 0.03), uniform(rng, 0.15, 0.25))
        return shape, uniform(rng, 0.2, 0.5), colour(rng, BOTTLE_COLOURS)
    if cls == "can":
        shape = Cylinder(uniform(rng, 0.026, 0.033), uniform(rng, 0.10, 0.16))
        return shape, uniform(rng, 0.15, 0.4), colour(rng, CAN_COLOURS)
    half = (uniform(rng, 0.03, 0.07), uniform(rng, 0.02, 0.035), uniform(rng, 0.04, 0.10))
    return Cuboid(half), uniform(rng, 0.1, 0.4), colour(rng, BOX_COLOURS)


def lighting(rng: np.random.Generator, hall: Hall) -> Lighting:
    """A tilted directional light over the hall and two to four ceiling spots, tinted."""
    tilt = rng.uniform(-0.3, 0.3, 2)
    down = np.array([tilt[0], tilt[1], -1.0])
    lights = [_light((0.0, 0.0, hall.wall_height + 2.0), down, uniform(rng, 0.3, 0.5), rng, True)]
    for _ in range(int(rng.integers(2, 5))):
        x = uniform(rng, hall.min_xy[0], hall.max_xy[0])
        y = uniform(rng, hall.min_xy[1], hall.max_xy[1])
        direction = np.array([*rng.uniform(-0.2, 0.2, 2), -1.0])
        lights.append(
            _light((x, y, hall.wall_height - 0.2), direction, uniform(rng, 0.2, 0.4), rng)
        )
    grey = uniform(rng, 0.15, 0.3)
    return Lighting(
        ambient=(grey, grey, grey * uniform(rng, 0.9, 1.1)),
        headlight_diffuse=(0.2, 0.2, 0.2) if rng.random() < 0.5 else (0.1, 0.1, 0.1),
        lights=tuple(lights),
    )


def _light(
    position: tuple[float, float, float],
    direction: NDArray[np.float64],
    intensity: float,
    rng: np.random.Generator,
    directional: bool = False,
) -> Light:
    tint = np.array([1.0, uniform(rng, 0.92, 1.0), uniform(rng, 0.85, 1.0)])
    if rng.random() < 0.5:
        tint = tint[::-1]  # cool instead of warm
    d = direction / np.linalg.norm(direction)
    r, g, b = intensity * tint
    spec = uniform(rng, 0.1, 0.3)
    return Light(
        position=position,
        direction=(float(d[0]), float(d[1]), float(d[2])),
        diffuse=(float(r), float(g), float(b)),
        specular=(spec, spec, spec),
        directional=directional,
    )
