"""The engine tier's slicing matrix: models, settings, and what the checks need to know.

Every case is sliced once per session with the real CuraEngine (see conftest.py).
Models are in model coordinates (centred on X/Y = 0, z >= 0); a second object is
placed by writing its STL already shifted by ``offset``.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import Polygon

from DelaunayInfill import models

from .gcode_check import DensityRegion, Part, SliceGeometry


@dataclass
class Model:
    """One mesh to slice: a prism stack (outline, z0, z1) shifted by `offset`."""

    name: str
    prisms: list  # [(outline (n, 2), z0, z1)]
    offset: tuple = (0.0, 0.0)
    per_mesh: dict = field(default_factory=dict)
    density_region: float | None = None  # an infill_mesh modifier of this density (fraction)

    def triangles(self) -> np.ndarray:
        tris = np.concatenate([models.prism(o, z1 - z0, z0) for o, z0, z1 in self.prisms])
        return tris + np.array([self.offset[0], self.offset[1], 0.0])

    def outline_polygon(self) -> Polygon:
        return Polygon(np.asarray(self.prisms[0][0]) + np.asarray(self.offset))


@dataclass
class Case:
    """A slicing configuration of the matrix."""

    name: str
    models: list[Model]
    settings: dict = field(default_factory=dict)

    def key(self) -> str:
        blob = json.dumps(
            [self.settings, [(m.name, m.triangles().round(6).tolist(), m.per_mesh) for m in self.models]],
            sort_keys=True, default=str,
        )
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    @property
    def density(self) -> float:
        return float(self.settings.get("infill_sparse_density", 20)) / 100.0

    def geometry(self, bed_offset=(110.0, 110.0)) -> SliceGeometry:
        parts = [
            Part(np.asarray(o), z0, z1, tuple(m.offset), m.name)
            for m in self.models if m.density_region is None
            for o, z0, z1 in m.prisms
        ]
        return SliceGeometry(parts, bed_offset)

    def regions(self, bed_offset=(110.0, 110.0)) -> list[DensityRegion]:
        from shapely.affinity import translate

        # (the matrix is sliced by CuraEngine 4.13, its modifiers wall-less infill meshes)
        return [
            DensityRegion(m.name, translate(m.outline_polygon(), *bed_offset), m.density_region, cura4_inset=True)
            for m in self.models if m.density_region is not None
        ]

    def mesh_densities(self) -> dict[str, float]:
        """`;MESH:` name -> density percent of the modifier meshes (for `--mesh NAME:PCT`)."""
        return {m.name: 100.0 * m.density_region for m in self.models if m.density_region is not None}


def cube_model(offset=(0.0, 0.0), name="cube.stl"):
    return Model(name, [(models.cube_outline(20.0), 0.0, 20.0)], offset)


def hbracket_model(name="hbracket.stl"):
    return Model(name, [(models.h_bracket_outline(), 0.0, 10.0)])


def star_model(offset=(0.0, 0.0), name="star.stl"):
    return Model(name, [(models.star_outline(), 0.0, 10.0)], offset)


def modifier_box(name, sx, sy, cx, cy, density_percent, height=12.0):
    from DelaunayInfill.curaengine import infill_modifier_settings

    outline = np.array([(cx - sx / 2, cy - sy / 2), (cx + sx / 2, cy - sy / 2),
                        (cx + sx / 2, cy + sy / 2), (cx - sx / 2, cy + sy / 2)])
    return Model(name, [(outline, 0.0, height)], per_mesh=infill_modifier_settings(density_percent),
                 density_region=density_percent / 100.0)


def star_figure10_modifiers() -> list[Model]:
    """The paper's Figure 10 split of the star (five tips, the centre) as infill_mesh modifiers."""
    from DelaunayInfill.curaengine import infill_modifier_settings

    out = []
    for name, polygon in models.star_regions().items():
        density = models.STAR_FIGURE10_DENSITIES[name]
        outline = np.asarray(polygon.exterior.coords)[:-1]
        out.append(Model(f"region_{name}.stl", [(outline, 0.0, 11.0)],
                         per_mesh=infill_modifier_settings(100 * density), density_region=density))
    return out


def plate_model(name="plate.stl"):
    """A 60 x 60 x 12 mm block."""
    return Model(name, [(models.cube_outline(60.0), 0.0, 12.0)])


def table_model(name="table.stl"):
    """A pillar under a wider slab: an overhang that needs support."""
    pillar = np.array([(-8.0, -8.0), (8.0, -8.0), (8.0, 8.0), (-8.0, 8.0)])
    slab = np.array([(-20.0, -15.0), (20.0, -15.0), (20.0, 15.0), (-20.0, 15.0)])
    return Model(name, [(pillar, 0.0, 6.0), (slab, 6.0, 10.0)])


def matrix() -> dict[str, Case]:
    """The issue's matrix: cube, H-bracket, star, star + two modifier boxes, two objects,
    one-at-a-time, relative extrusion, infill every 2nd layer, support, 10 % and 50 %; plus the
    paper's Figure 10 densities on the star as six infill_mesh modifiers."""
    cases = [
        Case("cube", [cube_model()]),
        Case("hbracket", [hbracket_model()]),
        Case("star", [star_model()]),
        Case("star_modifiers", [
            star_model(),
            modifier_box("box_dense.stl", 30.0, 22.0, 0.0, 17.0, 50.0),
            modifier_box("box_sparse.stl", 22.0, 18.0, 0.0, -13.0, 10.0),
        ]),
        Case("star_figure10", [star_model(), *star_figure10_modifiers()]),
        Case("two_objects", [cube_model((-35.0, 0.0)), star_model((25.0, 0.0))]),
        Case("one_at_a_time", [cube_model((-35.0, 0.0)), star_model((25.0, 0.0))],
             {"print_sequence": "one_at_a_time"}),
        Case("relative_e", [hbracket_model()], {"relative_extrusion": True}),
        Case("infill_every_2nd", [star_model()], {"infill_sparse_thickness": 0.4}),
        Case("support", [table_model()], {"support_enable": True}),
        # beyond the list: retraction variants the pipeline must hand back exactly
        Case("firmware_retraction", [star_model()], {"machine_firmware_retract": True}),
        Case("zhop_no_combing", [hbracket_model()],
             {"retraction_hop_enabled": True, "retraction_hop": 0.4, "retraction_combing": "off"}),
        # a sparse region enclosed by denser infill: printed as its own lattice up to its border
        Case("sparse_region_enclosed", [plate_model(), modifier_box("box_enclosed.stl", 36.0, 36.0, 0.0, 0.0, 10.0)],
             {"infill_sparse_density": 40}),
        # a dense region enclosed by sparser infill: its own lattice in whole triangles
        Case("dense_region_enclosed", [plate_model(), modifier_box("box_dense.stl", 30.0, 30.0, 0.0, 0.0, 60.0)],
             {"infill_sparse_density": 20}),
        Case("density_10", [hbracket_model()], {"infill_sparse_density": 10}),
        Case("density_50", [hbracket_model()], {"infill_sparse_density": 50}),
    ]
    return {c.name: c for c in cases}
