"""Parameters of a rock tile set, in the papers' names; they and the seed key the tile cache.

Lengths are in *cells*: a corner cube edge is ``n`` cells, and with one seed
per cell a rock is about one cell across. The scene's ``rock_size`` is the
size of a cell in metres.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from .seed_points import SeedParams

__all__ = ["ErosionParams", "TileParams", "TILINGS"]

TILINGS = ("aperiodic", "periodic")


@dataclass(frozen=True)
class ErosionParams:
    """Erosion controls (Peytavie et al. 2009, section 5).

    Parameters
    ----------
    steps : int
        Number of spheroidal erosion iterations.
    rate : float
        Erosion amount ``epsilon`` of a fully exposed voxel per iteration.
    contact_radius : float
        ``a``: no erosion within this distance of a contact point (cells).
    blend_radius : float
        ``b``: full erosion beyond this distance (cells), ``b > a``.
    smoothing : float
        Gaussian low-pass of ``rho`` before meshing, in voxels (0: off).
    """

    steps: int = 10
    rate: float = 0.5
    contact_radius: float = 0.12
    blend_radius: float = 0.35
    smoothing: float = 0.8

    def __post_init__(self):
        if not 0 <= self.steps <= 200:
            raise ValueError(f"erosion.steps must be in [0, 200] (got {self.steps})")
        if not 0.0 < self.rate <= 1.0:
            raise ValueError(f"erosion.rate must be in (0, 1] (got {self.rate})")
        if not 0.0 <= self.contact_radius < self.blend_radius <= 2.0:
            raise ValueError("erosion radii must satisfy 0 <= contact_radius < blend_radius <= 2 cells "
                             f"(got {self.contact_radius}, {self.blend_radius})")
        if not 0.0 <= self.smoothing <= 3.0:
            raise ValueError(f"erosion.smoothing must be in [0, 3] voxels (got {self.smoothing})")


@dataclass(frozen=True)
class TileParams:
    """Everything a tile set depends on.

    Parameters
    ----------
    tiling : {'aperiodic', 'periodic'}
        Corner cube tiles (rock-piles paper) or the single periodic tile (Arches).
    n : int
        Cells per corner cube edge (aperiodic, ``>= 4``; the paper: 5 to 7).
    voxels_per_cell : int
        ``V = n_G / n``; the paper uses ``n_G = 10 n``. Even.
    seed : int
        Random seed of the whole set.
    seeds : SeedParams
        Seed density and metric (aperiodic).
    erosion : ErosionParams
    poisson_radius : float
        Periodic tile: radius ``r`` of the Poisson spheres (centres at least
        ``2 r`` apart), in tile units; ``r = 0.1`` gives the 50-70 rocks per
        tile of the Arches paper (table 2).
    periodic_voxels : int
        Periodic tile: voxels per tile edge.
    anchors : int
        Anchor voxels stored per rock (plus its seed) for instancing.
    mesh_step : int
        Marching-cubes step in voxels. A rock too small for the step's grid is
        meshed at the next finer step that sees it (``rock_meshes.mesh_rock``).
    """

    tiling: str = "aperiodic"
    n: int = 5
    voxels_per_cell: int = 10
    seed: int = 0
    seeds: SeedParams = field(default_factory=SeedParams)
    erosion: ErosionParams = field(default_factory=ErosionParams)
    poisson_radius: float = 0.1
    periodic_voxels: int = 64
    anchors: int = 32
    mesh_step: int = 1

    def __post_init__(self):
        if self.tiling not in TILINGS:
            raise ValueError(f"tiling must be one of {', '.join(TILINGS)} (got {self.tiling!r})")
        if not 4 <= self.n <= 12:
            raise ValueError(f"n must be in [4, 12] (got {self.n})")
        if self.voxels_per_cell % 2 or not 4 <= self.voxels_per_cell <= 24:
            raise ValueError(f"voxels_per_cell must be even and in [4, 24] (got {self.voxels_per_cell})")
        if not 0.04 <= self.poisson_radius <= 0.3:
            raise ValueError(f"poisson_radius must be in [0.04, 0.3] tile units (got {self.poisson_radius})")
        if not 16 <= self.periodic_voxels <= 192:
            raise ValueError(f"periodic_voxels must be in [16, 192] (got {self.periodic_voxels})")
        if not 1 <= self.anchors <= 512:
            raise ValueError(f"anchors must be in [1, 512] (got {self.anchors})")
        if self.mesh_step not in (1, 2, 3):
            raise ValueError(f"mesh_step must be 1, 2 or 3 (got {self.mesh_step})")

    def to_dict(self) -> dict:
        """Plain data of every parameter that changes the tiles (the cache key's input)."""
        d = dataclasses.asdict(self)
        if self.tiling == "periodic":     # unused parameters must not split the cache
            d.pop("n"), d.pop("seeds"), d.pop("voxels_per_cell")
        else:
            d.pop("poisson_radius"), d.pop("periodic_voxels")
        return d
