"""The seamless layout's build: one sampling of the whole footprint, calibrated zone by zone.

`build_seamless` is the default layout of `pattern.InfillPattern.build`:

1. `plan`: what every sampling of the build shares: the zones' meter where the
   lines are printed, the area sampled (the footprint grown by the largest
   radius), what kind of calibration each zone allows and which zones are
   sparser or denser than all round them (`enclosed_zones`: sampled round as
   holes, each its own lattice).
2. `calibrated`: samplings at corrected densities (`sampled`, one sampling,
   its triangulation and how far each zone is off) while they bring the zones
   closer to their targets; the best is kept.
3. `finished`: what the radius could not reach (`calibration`: one zone
   scaled, several balanced edge by edge) and crowded nodes thinned.
4. Several zones on lattices: other samplings of the Poisson-disk samples
   between the lattices where a zone's band along a denser zone prints off its
   density (`calibration.settled_bands`).

Densities are fractions, lengths mm.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from shapely.ops import unary_union

from .calibration import TOLERANCE, balance_zones, edge_cache, fine_tune_scale, scale_limit, settled_bands
from .density import LATTICE_SIDE, DensityMap, sampling_radius, shortest_edges
from .enclosed_zones import BORDER_GAP, border_samples, enclosed_zones, hole_lines, lattice_patch
from .geometry import contains_xy, to_multipolygon
from .metering import measured_density, meter_for
from .sampling import LATTICE_SPACING, sample_lattice, sample_poisson_disk, sample_triangulated
from .triangulation import (
    GrowingDelaunay,
    delaunay_triangles,
    growing_delaunay,
    relax_points,
    uncrowded_edges,
    unique_edges,
)

__all__ = ["Sampling", "SeamlessBuild", "build_seamless", "plan"]

_MAX_ITERATIONS = 8
_LOOP_TOLERANCE = 0.003  # several zones: the loop stops within 0.3 points (balancing does the rest)
_SLIVER = 1.5  # hull triangles with a circumradius above 1.5 r are not part of the pattern
_SMALL = 16.0  # several zones: a zone under this many squared radii is calibrated by balancing, not the radius
_COARSE = 36.0  # several zones: a zone under this many squared radii is only balanced once off target
# line widths: the denser zone's samples round an enclosed sparse zone lie this far outside it, so that
# the ring of lines they make lies on the denser side (its bead touches the border from outside): the
# zone is its lattice up to its border (40 seeds, `bench/bench_regions.py`: a 10 % zone in 40 % 0.940 ->
# 0.962 of a uniform pattern's C_min / rho over it, a 24 mm one's worst density error 2.27 -> 1.38 points)
RING_OUTSIDE = 0.5
# a dense enclosed zone is its own lattice (a patch) only where it holds at least this many squared lattice
# sides and the patch's lines print at most this far (a fraction) under its density: whole triangles leave
# the border strip to the joining lines, which make up 0.4-2 points (`_enclosed`)
PATCH_AREA = 24.0
PATCH_SHORTFALL = 0.02


@dataclass
class Sampling:
    """One sampling of the seamless build's calibration: its pattern and how far its zones are off."""

    worst: float  # the worst zone's error (fraction; in the loop small zones above target count a quarter)
    points: np.ndarray  # (n, 2) mm
    triangles: np.ndarray  # (t, 3) indices into points
    segments: np.ndarray  # (e, 2, 2) mm: the edges kept
    measured: np.ndarray  # (zones,) fractions
    iteration: int  # of the calibration loop
    edges: np.ndarray  # (e, 2) indices into points (as sampled: balancing changes `segments` only)
    inside: np.ndarray  # (zones, e) mm of each of those edges inside each zone
    growing: object  # its GrowingDelaunay, or None
    fixed: int  # how many of the first points lie on a lattice
    factors: np.ndarray  # (zones,) the density factors it was sampled at
    band_error: float = 0.0  # the worst border band's error (fraction), where measured
    extra: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2, 2)))  # (x, 2, 2) mm: the
    # enclosed zones' lattice lines, the last x of `segments` (no edges of `points`)


@dataclass(frozen=True)
class SeamlessBuild:
    """What every sampling of one seamless build shares.

    Attributes
    ----------
    area : shapely MultiPolygon
        The footprint, mm.
    printed : shapely MultiPolygon
        Where the lines will be printed (inside `area`): the zones are measured there.
    dmap : DensityMap
    width : float
        Line width, mm.
    seed : int
    calibration : {"measured", "paper"}
    relax : int
        Lloyd relaxation steps.
    sampler : {"lattice", "fast", "bridson"}
    meter : ZoneMeter or RasterMeter
        The zones where the lines are printed.
    sampling_area : shapely MultiPolygon
        The footprint grown by the largest radius (the pattern reaches past the border), without the
        enclosed zones.
    targets : ndarray, shape (zones,)
        Target densities.
    settled : ndarray of bool, shape (zones,)
        Zones with area where the lines are printed.
    small, coarse : ndarray of bool, shape (zones,)
        Several zones: zones under about 4 x 4 (`_SMALL`) and 6 x 6 (`_COARSE`) of their own radii.
    single : bool
        One zone, measured calibration: calibrated by scaling one sampling.
    limit : float
        How far the pattern may be scaled (`calibration.scale_limit`).
    growing : bool
        The samplings keep a growing triangulation (balancing refines it).
    surround : ndarray of int, shape (zones,)
        For a zone enclosed by denser ones or by sparser ones (`enclosed_zones`), the zone whose density
        it is sampled at (it is a hole in the sampling, filled with its own lattice); else -1.
    zone_areas : tuple of MultiPolygon
        The zones over the sampling area (`DensityMap.zones`), for the enclosed ones.
    cut : shapely MultiPolygon or None
        The enclosed zones together (a dense one as its patch).
    patches : dict of int to LatticePatch
        The dense enclosed zones' own lattices (`enclosed_zones.lattice_patch`).
    rings : dict of int to MultiPolygon
        The sparse enclosed zones grown by `RING_OUTSIDE` line widths: their border samples lie on it.
    """

    area: object
    printed: object
    dmap: DensityMap
    width: float
    seed: int
    calibration: str
    relax: int
    sampler: str
    meter: object
    sampling_area: object
    targets: np.ndarray
    settled: np.ndarray
    small: np.ndarray
    coarse: np.ndarray
    single: bool
    limit: float
    growing: bool
    surround: np.ndarray = None
    zone_areas: tuple = ()
    cut: object = None
    patches: dict = dataclasses.field(default_factory=dict)
    rings: dict = dataclasses.field(default_factory=dict)

    def radius_of(self, density):
        """Poisson-disk radius (mm) first taken for `density` (fraction or array of them)."""
        return sampling_radius(density, self.width, self.calibration)

    @property
    def several(self) -> bool:
        """More than one zone where the lines are printed."""
        return bool(np.count_nonzero(self.settled) > 1)

    @property
    def loop_tolerance(self) -> float:
        """The calibration loop stops at this worst zone error (fraction)."""
        return TOLERANCE if self.single else _LOOP_TOLERANCE

    @property
    def patched(self) -> np.ndarray:
        """(zones,) bool: the dense enclosed zones, printed as their `patches`."""
        return np.isin(np.arange(len(self.targets)), list(self.patches))

    @property
    def holes(self) -> np.ndarray:
        """(zones,) bool: the enclosed zones."""
        return np.zeros(len(self.targets), bool) if self.surround is None else self.surround >= 0


def build_seamless(area, dmap: DensityMap, width: float, seed: int, calibration: str, relax: int, sampler: str,
                   printed) -> Sampling:
    """The seamless layout's pattern over `area`, calibrated where it is `printed`.

    The parameters are `SeamlessBuild`'s attributes of the same names, checked by
    `pattern.InfillPattern.build`.

    Returns
    -------
    Sampling
        The calibrated, thinned pattern.
    """
    build = plan(area, dmap, width, seed, calibration, relax, sampler, printed)
    done = finished(build, calibrated(build))
    if build.sampler == "lattice" and build.growing and build.several:
        # (a coarse zone's band: one sampling to the next moves it by jumps, as the zone itself)
        # (a zone round a dense zone's own lattice prints that lattice's reach in its band: not a chance to undo)
        hosts = np.isin(np.arange(len(build.targets)), build.surround[build.patched])
        done = settled_bands(done, lambda between_seed: finished(build, calibrated(build, between_seed)),
                             dmap.zones(printed), build.targets, width, build.settled & ~build.coarse & ~hosts,
                             printed)
    return done


def plan(area, dmap: DensityMap, width: float, seed: int, calibration: str, relax: int, sampler: str,
         printed) -> SeamlessBuild:
    """What the samplings of one build share (`build_seamless`'s parameters)."""
    if sampler == "lattice" and dmap.feather > 0:
        # A feathered border varies the radius over a band the lattices leave to the Poisson-disk
        # samples (measured there, `fast` keeps the blend closer to the map): `fast` throughout.
        sampler = "fast"
    # Measured where the lines are printed (a lattice a few sides across a small part prints a ring
    # round it that the infill area has not; a mesh's extent holds places it never prints).
    meter = meter_for(printed, dmap, width)
    zone_areas = meter.areas
    targets = np.array(dmap.densities)
    reach = 1.3 * sampling_radius(float(min(targets)), width, calibration)
    # Simplified first: buffering a footprint with many short (rounded) edges by a large
    # reach is slow; the simplified outline is within `tol` of it, so grow by reach + tol.
    tol = 0.05 * reach
    sampling_area = to_multipolygon(area.simplify(tol).buffer(reach + tol, 8))
    settled = zone_areas > 0
    radius_squared = np.array([sampling_radius(t, width, calibration) ** 2 for t in targets.tolist()])
    several = np.count_nonzero(settled) > 1
    # Zones under about 4 x 4 of their own radii cannot be calibrated by the radius alone; they are
    # balanced by thinning or refinement at the end.  (A single zone is fine-tuned by scaling instead.)
    small = settled & (zone_areas < _SMALL * radius_squared) & several
    # Zones under about 6 x 6 of their radii hold a few dozen samples: one sampling to the
    # next moves them by several points, so re-sampling for them alone is noise.
    coarse = settled & (zone_areas < _COARSE * radius_squared)
    # A single zone is calibrated by scaling one sampling (continuous, cheap) as soon as
    # the scale needed is within reach; re-sampling only moves it by jumps of 1-2 points.
    single = calibration == "measured" and np.count_nonzero(settled) == 1
    surround, zone_areas, cut, patches, rings = None, (), None, {}, {}
    if sampler == "lattice" and calibration == "measured" and several and not relax:
        zone_areas = tuple(dmap.zones(sampling_area))
        surround, patches = _enclosed(dmap, zone_areas, area, np.sqrt(radius_squared), settled, width, seed)
        if (surround >= 0).any():  # (sampled round, as holes)
            cut = to_multipolygon(unary_union([patches[k].area if k in patches else zone_areas[k]
                                               for k in np.flatnonzero(surround >= 0)]))
            # the sparser samples keep their distance from a patch: its outline's nodes join them
            clear = [patch.area.buffer(BORDER_GAP * math.sqrt(radius_squared[surround[k]]), 4)
                     for k, patch in patches.items()]
            sampling_area = to_multipolygon(sampling_area.difference(unary_union([cut, *clear])))
            rings = {k: zone_areas[k].buffer(RING_OUTSIDE * width, 4)
                     for k in np.flatnonzero(surround >= 0).tolist() if k not in patches}
    return SeamlessBuild(area, printed, dmap, width, seed, calibration, relax, sampler, meter, sampling_area,
                         targets, settled, small, coarse, bool(single), scale_limit(area, reach),
                         not single and calibration == "measured", surround, zone_areas, cut, patches, rings)


def sampled(build: SeamlessBuild, factors: np.ndarray, iteration: int, between_seed: int | None = None) -> Sampling:
    """One sampling at the densities ``targets * factors`` (zones,), triangulated and measured."""
    densities = build.targets * factors
    # An enclosed zone is sampled at its surroundings' density and left out: a hole in the sampling.
    sampled_at = np.where(build.holes, densities[np.maximum(build.surround, 0)], densities) \
        if build.holes.any() else densities
    scaled = build.dmap.with_densities(sampled_at)

    def radius_fn(xy):
        return build.radius_of(scaled.at(xy))

    # Several zones may be balanced afterwards: it goes on from a growing triangulation.
    points, fixed, growing = _sample(build.sampling_area, radius_fn, build.seed, build.sampler, build.relax,
                                     growing=build.growing, between_seed=between_seed)
    border = _on_hole_borders(build, points, sampled_at)  # the denser zones' triangles reach them
    points = np.concatenate((points, border))
    triangles, edges = _triangulate(points, growing, radius_fn, build.dmap, build.width, build.cut, len(border))
    extra = _hole_lattices(build, points, triangles, densities, sampled_at)
    if build.patches:
        edges = edges[~_on_patches(points[edges], build)]
    segments = np.concatenate((points[edges], extra))
    inside = build.meter.inside_all(segments)
    measured = build.meter.densities_of(inside, build.width)
    inside = inside[:, :len(edges)]
    error = np.abs(measured - build.targets)
    # Small zones above target can be thinned afterwards; shortfalls cannot.
    error = np.where(build.small & (measured > build.targets), 0.25 * error, error)
    # (a dense zone's patch is its exact lattice: no factor moves it)
    worst = float(np.nanmax(np.where(build.settled & ~build.patched, error, 0.0))) if len(error) else 0.0
    return Sampling(worst, points, triangles, segments, measured, iteration, edges, inside, growing, fixed,
                    factors.copy(), extra=extra)


def calibrated(build: SeamlessBuild, between_seed: int | None = None) -> Sampling:
    """The calibration loop: the best of up to `_MAX_ITERATIONS` samplings at corrected densities."""
    factors = np.ones(len(build.targets))
    bracket = np.array([0.0, np.inf])  # single zone: factors known to print too sparse / too dense
    best = None
    for iteration in range(1, _MAX_ITERATIONS + 1):
        tried = sampled(build, factors, iteration, between_seed)
        if best is None or tried.worst < best.worst:
            best = tried
        if build.calibration == "paper" or tried.worst <= build.loop_tolerance:
            break
        step, ok = _density_step(build, tried.measured)
        if build.single:
            factors = _single_zone_factors(build, factors, bracket, tried.measured, step, ok)
        elif iteration - best.iteration >= 2:  # two samplings without improvement: the rest is noise
            factors = None
        elif not (build.settled & ~build.coarse & (np.abs(tried.measured - build.targets) > _LOOP_TOLERANCE)).any():
            factors = None  # only coarse zones are off: balancing (`finished`) does better than re-sampling
        else:
            # Half steps (in log scale) down: small zones respond in jumps and full steps would
            # oscillate; zones that fall short take full steps up, since what ends up too dense
            # can be thinned afterwards.
            factors = factors * np.where(build.small & (step > 1.0), step, np.sqrt(step))
        if factors is None:
            break
    return best


def _density_step(build: SeamlessBuild, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The factor (zones,) each zone's density is off by (target / measured, within 1/2 and 2) and
    which zones printed something measurable (zones,) bool."""
    ok = build.settled & np.isfinite(measured) & (measured > 0)
    step = np.where(ok, build.targets / np.where(ok, measured, 1.0), 1.0)
    step = np.where(build.settled & ~ok, 2.0, step)  # a zone with nothing printed: denser
    return np.clip(step, 0.5, 2.0), ok


def _single_zone_factors(build: SeamlessBuild, factors: np.ndarray, bracket: np.ndarray, measured: np.ndarray,
                         step: np.ndarray, ok: np.ndarray) -> np.ndarray | None:
    """A single zone's next density factors (zones,), or None once scaling can reach the target.

    Newton steps (density ~ 1 / r), kept inside the `bracket` of factors known to print too sparse /
    too dense (coarse patterns print in jumps; updated in place), else its geometric middle.
    """
    k = int(np.flatnonzero(build.settled)[0])
    # density ~ 1 / scale: the scale that hits the target is 1 / step
    if ok[k] and abs(1.0 / float(step[k]) - 1.0) <= 0.8 * build.limit:
        return None
    if measured[k] > build.targets[k]:
        bracket[1] = min(bracket[1], float(factors[k]))
    else:
        bracket[0] = max(bracket[0], float(factors[k]))
    proposal = float(factors[k] * step[k])
    if not bracket[0] < proposal < bracket[1]:
        proposal = math.sqrt(bracket[0] * bracket[1]) if np.isfinite(bracket).all() else proposal
    factors = factors.copy()
    factors[k] = proposal
    return factors


def finished(build: SeamlessBuild, best: Sampling) -> Sampling:
    """The sampling calibrated on: what the radius could not reach, and crowded nodes thinned."""
    meter, targets, width, settled = build.meter, build.targets, build.width, build.settled
    points, triangles, segments, measured = best.points, best.triangles, best.segments, best.measured
    extra, holes = best.extra, build.holes
    segments = segments[:len(segments) - len(extra)]
    if build.single and best.worst > TOLERANCE / 4:
        points, segments, measured = fine_tune_scale(points, best.edges, meter, targets, measured, width,
                                                     build.limit, build.area)
    elif build.calibration == "measured" and best.worst > TOLERANCE and build.several:
        # Zones still off target after calibration (small ones, or dense ones next to a
        # sparse neighbour that keeps their samples apart) are balanced edge by edge.
        off = build.small | (settled & np.isfinite(measured) & (np.abs(measured - targets) > TOLERANCE))
        off &= ~holes  # (an enclosed zone's lines are its lattice's: nothing to balance)
        # The edges' inside lengths are known already: balancing measures only new edges.
        points, triangles, segments, measured = balance_zones(
            points, triangles, meter, targets, width, off, known=edge_cache(best.edges, best.inside),
            growing=best.growing, limit=lambda segs: uncrowded(segs, build.dmap, width), fixed=best.fixed)
    if holes.any():  # refinement's triangles may span a hole again
        segments = segments[~_across(segments, build)]
        if build.patches:
            segments = segments[~_on_patches(segments, build)]
    # (the enclosed zones' lines count at their nodes but stay: they are those zones' lattices)
    keep = uncrowded(np.concatenate((segments, extra)), build.dmap, width,
                     fixed=np.arange(len(segments) + len(extra)) >= len(segments))[:len(segments)]
    if not keep.all() or holes.any():
        segments = np.concatenate((segments[keep], extra))
        measured = meter.densities_of(meter.inside_all(segments), width)
    error = np.where(settled, np.abs(measured - targets), 0.0)
    return dataclasses.replace(best, points=points, triangles=triangles, segments=segments,
                               measured=np.asarray(measured), worst=float(np.nanmax(error)) if len(error) else 0.0)


def uncrowded(segments: np.ndarray, dmap: DensityMap, width: float, fixed: np.ndarray | None = None) -> np.ndarray:
    """`uncrowded_edges` of segments (k, 2, 2) mm, the shortest a quarter of the local spacing: keep mask (k,).

    `fixed` (k,) bool, optional: segments never left out (they count at their nodes)."""
    return uncrowded_edges(segments, shortest_edges(segments, dmap, width), fixed=fixed)


def _sample(area, radius_fn, seed: int, sampler: str, relax: int, growing: bool, between_seed: int | None = None):
    """Samples of `area` at the radius field `radius_fn` (one pass of the seamless build).

    Parameters
    ----------
    area : shapely MultiPolygon
        The sampling area (the footprint grown by the largest radius), mm.
    radius_fn : callable
        Points (m, 2) mm -> radius (m,) mm.
    seed : int
    sampler : {"lattice", "fast", "bridson"}
    relax : int
        Lloyd relaxation steps.
    growing : bool
        Also a growing triangulation of the samples (balancing refines it): qhull's
        incremental one, the sampler's own when it made one (the same triangles).
    between_seed : int, optional
        ``"lattice"``: another sampling of the Poisson-disk samples between the lattices.

    Returns
    -------
    (points, fixed, growing)
        The samples (n, 2) mm; how many of the first lie on a lattice; a `GrowingDelaunay`
        of them, or None (not asked for, or qhull refuses the points).
    """
    if growing and sampler in ("fast", "lattice") and not relax:
        points, qhull, fixed = sample_triangulated(area, radius_fn, seed=seed, lattice=sampler == "lattice",
                                                   between_seed=between_seed if sampler == "lattice" else None)
        return points, fixed, GrowingDelaunay(points, qhull) if qhull is not None else growing_delaunay(points)
    fixed = 0  # relaxation leaves lattice points where they are (they are the regular part)
    if sampler == "lattice":
        points, fixed = sample_lattice(area, radius_fn, seed=seed, between_seed=between_seed)
    else:
        points = sample_poisson_disk(area, radius_fn, seed=seed, method=sampler)
    if relax:
        points = relax_points(points, area, radius_fn, relax, seed=seed, fixed=fixed)
    return points, fixed, growing_delaunay(points) if growing else None


def _enclosed(dmap: DensityMap, zone_areas: tuple, area, radii: np.ndarray, settled: np.ndarray, width: float,
              seed: int) -> tuple[np.ndarray, dict]:
    """The zones sampled round as holes (`SeamlessBuild.surround`) and the dense ones' lattice patches
    (`SeamlessBuild.patches`).

    A dense zone gets a patch where it holds at least `PATCH_AREA` squared lattice sides and the patch's
    own lines print at most `PATCH_SHORTFALL` under its density; else it is sampled with the zones round it
    (balancing brings a small zone to its density: a 12 mm disk at 60 % in 20 % printed 54.4-61.0 % as a
    patch, within 1.2 points sampled; `bench/bench_regions.py --seeds 40`).

    A zone that a sparse zone is sampled round is sampled itself (no patch), and a patch reaches only
    into the zone round it, clear of the other enclosed zones by as far as their own lines reach out
    (a patch's height, a sparse zone's two radii, `hole_lines`): two of them never overlap."""
    surround = enclosed_zones(dmap, list(zone_areas), area, radii, settled, denser=False)
    dense = enclosed_zones(dmap, list(zone_areas), area, radii, settled, denser=True)
    dense[np.isin(np.arange(len(dense)), surround[surround >= 0])] = -1
    sides = {k: LATTICE_SIDE * width / float(dmap.densities[k]) for k in np.flatnonzero(dense >= 0).tolist()}
    sides = {k: side for k, side in sides.items() if zone_areas[k].area >= PATCH_AREA * side * side}
    reach_out = {k: math.sqrt(3.0) / 2.0 * side for k, side in sides.items()}
    reach_out.update({k: 2.0 * float(radii[surround[k]]) for k in np.flatnonzero(surround >= 0).tolist()})
    patches = {}
    for k, side in sides.items():
        others = [zone_areas[j].buffer(reach, 4) for j, reach in reach_out.items() if j != k]
        room = zone_areas[dense[k]].difference(unary_union(others)) if others else zone_areas[dense[k]]
        patch = lattice_patch(zone_areas[k], side, seed, room)
        # (whole triangles print under the zone's density by how the lattice meets its border; the zone
        # is sampled with the rest where they print too little for the joining lines to make up)
        if patch is not None and (measured_density(patch.lines, zone_areas[k], width)
                                  >= float(dmap.densities[k]) - PATCH_SHORTFALL):
            patches[k] = patch
            surround[k] = dense[k]
    return surround, patches


def _on_hole_borders(build: SeamlessBuild, points: np.ndarray, sampled_at: np.ndarray) -> np.ndarray:
    """Samples (m, 2) mm on the enclosed zones' borders, spaced for the zones round them: on a dense zone's
    patch outline (`LatticePatch.joins`), round a sparse zone `RING_OUTSIDE` line widths out."""
    return np.concatenate([np.zeros((0, 2))] + [
        build.patches[k].joins(build.zone_areas[k], points, float(build.radius_of(sampled_at[k])))
        if k in build.patches else
        border_samples(build.rings[k], points, float(build.radius_of(sampled_at[k])))
        for k in np.flatnonzero(build.holes)])


def _on_patches(segments: np.ndarray, build: SeamlessBuild) -> np.ndarray:
    """(k,) bool: segments (k, 2, 2) mm on a dense zone's patch (`LatticePatch.over`)."""
    out = np.zeros(len(segments), bool)
    for patch in build.patches.values():
        out |= patch.over(segments)
    return out


def _hole_lattices(build: SeamlessBuild, points: np.ndarray, triangles: np.ndarray, densities: np.ndarray,
                   sampled_at: np.ndarray) -> np.ndarray:
    """The enclosed zones' lattice lines (x, 2, 2) mm at their `densities`, joined to the samples round them."""
    return np.concatenate([np.zeros((0, 2, 2))] + [
        build.patches[k].lines if k in build.patches else
        hole_lines(build.zone_areas[k], points, triangles, LATTICE_SPACING * float(build.radius_of(densities[k])),
                   build.seed, float(build.radius_of(sampled_at[k]))) for k in np.flatnonzero(build.holes)])


def _across(segments: np.ndarray, build: SeamlessBuild) -> np.ndarray:
    """(k,) bool: segments (k, 2, 2) mm whose middle or quarter points lie inside an enclosed zone shrunk
    by a quarter of the smallest radius (a line across it, not one along its border)."""
    t = np.array([0.25, 0.5, 0.75])
    probes = (segments[:, None, 0] + t[None, :, None] * (segments[:, None, 1] - segments[:, None, 0])).reshape(-1, 2)
    core = build.cut.buffer(-0.25 * float(build.radius_of(float(build.targets.max()))), 4)
    if core.is_empty:
        return np.zeros(len(segments), bool)
    return contains_xy(core, probes[:, 0], probes[:, 1]).reshape(-1, 3).any(axis=1)


def _triangulate(points: np.ndarray, growing, radius_fn, dmap: DensityMap, width: float, cut=None, more: int = 0):
    """The pattern of samples (n, 2) mm: Delaunay triangles without hull slivers, and their edges.

    Crowded nodes are thinned before anything is measured (`uncrowded`): the calibration makes
    up for what they lose.  `growing` (`GrowingDelaunay`, optional): the samples' triangulation.
    `cut` (optional): the enclosed zones, which no triangle's centre may lie in; `more`: how many of
    the last points `growing` has not had yet (the samples on their borders).

    Returns
    -------
    (triangles, edges)
        Triangles (t, 3) and the edges kept (e, 2), indices into `points`.
    """
    triangles = delaunay_triangles(points) if growing is None else growing.add(points[len(points) - more:])
    triangles = _drop_slivers(points, triangles, radius_fn)
    if cut is not None and len(triangles):  # none across an enclosed zone
        centre = points[triangles].mean(axis=1)
        triangles = triangles[~contains_xy(cut, centre[:, 0], centre[:, 1])]
    edges = unique_edges(triangles)
    return triangles, edges[uncrowded(points[edges], dmap, width)]


def _drop_slivers(points: np.ndarray, triangles: np.ndarray, radius_fn) -> np.ndarray:
    """Triangles (t, 3) without the hull ones whose circumradius exceeds `_SLIVER` x the local radius."""
    if len(triangles) == 0:
        return triangles
    a, b, c = (points[triangles[:, k]] for k in range(3))
    la = np.hypot(*(b - c).T)
    lb = np.hypot(*(c - a).T)
    lc = np.hypot(*(a - b).T)
    twice_area = np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    circumradius = la * lb * lc / np.maximum(2.0 * twice_area, 1e-300)
    local = radius_fn(points)[triangles].max(axis=1)  # the radius at each corner, the largest
    return triangles[circumradius <= _SLIVER * local]
