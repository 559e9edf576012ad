"""Checking a processed G-code against its original: the pipeline's correctness contract.

``verify(original, processed)`` checks, chunk by chunk:

* every line outside FILL blocks is identical (``;TIME_ELAPSED`` values and the
  header's time/filament figures and marker excepted);
* after every FILL block the machine state (X, Y, Z, E register, retraction
  depth, firmware retraction, feedrate, extruder, E mode) equals the original's;
* rewritten blocks extrude the same E per mm as Cura's block (times `flow`);
* no extrusion move jumps E (E/mm at most twice Cura's largest in the layer)
  and no E-only move exceeds Cura's largest retraction;
* new infill lies inside the layer's infill area (length fraction outside a
  one-line-width tolerance);
* every place that had infill still has infill nearby.

Used by the tests and by ``delaunay-infill process --verify``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..geometry import contains_xy, multilinestring_of
from .area import mesh_layer, sample_segments, segments_of
from .infer import e_per_mm, wall_line_width
from .read import FILL, MARKER, MachineState, RetractionModel, iter_chunks, parse_layer

__all__ = ["Verification", "verify", "verify_files"]

_HEADER_FIGURES = re.compile(r"^;(TIME:|PRINT\.TIME:|Filament used:|MATERIAL2?:|EXTRUDER_TRAIN\.\d+\.MATERIAL\.VOLUME_USED:)")


@dataclass
class Verification:
    """Result of `verify`; ``ok`` when ``problems`` is empty."""

    problems: list[str] = field(default_factory=list)
    lines_compared: int = 0
    blocks_compared: int = 0
    blocks_rewritten: int = 0
    max_e_per_mm_error: float = 0.0
    outside_fraction: float = 0.0
    uncovered_fraction: float = 0.0
    new_infill_mm: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.problems

    def summary(self) -> str:
        head = "OK" if self.ok else f"{len(self.problems)} problem(s)"
        return (
            f"verify: {head}; {self.lines_compared} lines and {self.blocks_compared} FILL blocks compared, "
            f"{self.blocks_rewritten} rewritten; E/mm error max {self.max_e_per_mm_error * 100:.2f} %, "
            f"infill outside area {self.outside_fraction * 100:.2f} %, old infill uncovered {self.uncovered_fraction * 100:.2f} %"
        )


def _kept_lines(parse) -> list[str]:
    skip = np.zeros(len(parse.lines), dtype=bool)
    for b in parse.blocks:
        skip[b.start + 1 : b.stop] = True
    out = []
    for i, line in enumerate(parse.lines):
        if skip[i]:
            continue
        if line.startswith(";TIME_ELAPSED:"):
            out.append(";TIME_ELAPSED:")
        elif line.startswith(MARKER) or _HEADER_FIGURES.match(line):
            continue
        else:
            out.append(line)
    return out


def _state_diff(a: MachineState, b: MachineState) -> str:
    checks = [
        ("X", a.x, b.x, 2e-3),
        ("Y", a.y, b.y, 2e-3),
        ("Z", a.z, b.z, 1e-6),
        ("E", a.e, b.e, 2e-5) if not a.relative_e else ("E", 0.0, 0.0, 1.0),
        ("retraction depth", a.depth, b.depth, 2e-4),
        ("F", a.f, b.f, 1e-6),
    ]
    for name, u, v, tol in checks:
        if np.isnan(u) and np.isnan(v):
            continue
        if not abs(u - v) <= tol:
            return f"{name} {v:g} instead of {u:g}"
    if a.fw_retracted != b.fw_retracted:
        return "firmware retraction state differs"
    if a.extruder != b.extruder:
        return "extruder differs"
    if a.relative_e != b.relative_e:
        return "E mode differs"
    return ""


def verify(
    original: Iterable[str],
    processed: Iterable[str],
    *,
    flow: float = 1.0,
    line_width: float | None = None,
    coverage_radius: float | None = None,
    min_density: float = 0.1,
    max_problems: int = 20,
) -> Verification:
    """Compare a processed G-code with its original (both as chunk lists or Cura's list form).

    Parameters
    ----------
    original, processed : iterable of str
    flow : float
        The flow multiplier used for processing.
    line_width : float, optional
        mm; inferred from the walls when None.
    coverage_radius : float, optional
        mm; an original FILL point counts as covered when new infill lies this
        close (default: 2.5 line widths / `min_density`, about the largest
        distance from a point in a Delaunay cell to its edges).
    min_density : float
        The lowest infill density used (fraction).
    """
    res = Verification()
    a_chunks = list(iter_chunks(original))
    b_chunks = list(iter_chunks(processed))
    if len(a_chunks) != len(b_chunks):
        res.problems.append(f"chunk count differs: {len(b_chunks)} instead of {len(a_chunks)}")
        return res
    sa, sb = MachineState(), MachineState()
    ra, rb = RetractionModel(), RetractionModel()
    outside_len = total_len = 0.0
    uncovered = covered_total = 0
    lw = line_width
    max_eonly = 0.0

    def problem(msg):
        if len(res.problems) < max_problems:
            res.problems.append(msg)

    for ca, cb in zip(a_chunks, b_chunks, strict=True):
        pa = parse_layer(ca, sa, ra)
        pb = parse_layer(cb, sb, rb)
        where = f"layer {pa.number}" if pa.number is not None else "header/start/end"
        ka, kb = _kept_lines(pa), _kept_lines(pb)
        res.lines_compared += len(ka)
        if ka != kb:
            for i, (x, y) in enumerate(zip(ka, kb, strict=False)):
                if x != y:
                    problem(f"{where}: non-FILL line changed: {x!r} -> {y!r} (kept line {i})")
                    break
            else:
                problem(f"{where}: non-FILL line count differs ({len(kb)} instead of {len(ka)})")
        if len(pa.blocks) != len(pb.blocks):
            problem(f"{where}: FILL block count differs")
            continue
        ma, mb = pa.moves, pb.moves
        moved_a = (ma["x1"] != ma["x0"]) | (ma["y1"] != ma["y0"])
        moved_b = (mb["x1"] != mb["x0"]) | (mb["y1"] != mb["y0"])
        extr_a = moved_a & (ma["de"] > 0)
        extr_b = moved_b & (mb["de"] > 0)
        if lw is None and pa.number is not None and pa.number >= 1:
            for mesh in pa.meshes:
                w = wall_line_width(pa, mesh)
                if w is not None:
                    lw = w
                    break
        width = lw or 0.4
        fill_a = extr_a & (ma["kind"] == FILL)
        max_epm = 0.0
        if (extr_a & moved_a).any():
            la = np.hypot(ma["x1"] - ma["x0"], ma["y1"] - ma["y0"])
            ok = extr_a & (la > 0.05)
            if ok.any():
                max_epm = float((ma["de"][ok] / la[ok]).max())
        if (~moved_a).any():
            max_eonly = max(max_eonly, float(np.abs(ma["de"][~moved_a]).max()))
        lb = np.hypot(mb["x1"] - mb["x0"], mb["y1"] - mb["y0"])
        if max_epm > 0:
            ok = extr_b & (lb > 0.05)
            if ok.any() and (mb["de"][ok] / lb[ok]).max() > 2 * max_epm * max(flow, 1.0) + 1e-9:
                problem(f"{where}: an extrusion move jumps E ({(mb['de'][ok] / lb[ok]).max():.4g} per mm)")
        eonly_b = np.abs(mb["de"][~moved_b]) if (~moved_b).any() else np.zeros(0)
        if eonly_b.size and eonly_b.max() > max_eonly + 1e-4:
            problem(f"{where}: an E-only move of {eonly_b.max():.5g} exceeds Cura's largest ({max_eonly:.5g})")
        rewritten_meshes = set()
        for bi, (ba, bb) in enumerate(zip(pa.blocks, pb.blocks, strict=True)):
            res.blocks_compared += 1
            diff = _state_diff(ba.after, bb.after)
            if diff:
                problem(f"{where}: state after FILL block {bi} ({ba.mesh}): {diff}")
            old = pa.lines[ba.start : ba.stop]
            new = pb.lines[bb.start : bb.stop]
            if old == new:
                continue
            res.blocks_rewritten += 1
            rewritten_meshes.add(ba.mesh)
            # Retractions must pair up: the net E of E-only moves equals Cura's in this block.
            eonly_a = float(ma["de"][(ma["block"] == bi) & ~moved_a].sum())
            eonly_b = float(mb["de"][(mb["block"] == bi) & ~moved_b].sum())
            if abs(eonly_a - eonly_b) > 1e-4:
                problem(f"{where}: FILL block {bi} retracts/primes a net {eonly_b:+.5g} instead of Cura's {eonly_a:+.5g}")
            # E must not run backwards during a move (a register off by a retraction does that)
            back_a = int(((ma["block"] == bi) & moved_a & (ma["de"] < 0)).sum())
            back_b = int(((mb["block"] == bi) & moved_b & (mb["de"] < 0)).sum())
            if back_b > back_a:
                problem(f"{where}: FILL block {bi} has {back_b} moves whose E runs backwards (Cura's: {back_a})")
            mask_b = (mb["block"] == bi) & extr_b
            mask_a = (ma["block"] == bi) & extr_a
            ea = e_per_mm(pa, mask_a) or e_per_mm(pa, fill_a & pa.mesh_mask(ba.mesh)) or e_per_mm(pa, fill_a)
            eb = e_per_mm(pb, mask_b)
            if ea and eb:
                err = abs(eb / (ea * flow) - 1.0)
                res.max_e_per_mm_error = max(res.max_e_per_mm_error, err)
                if err > 0.01:
                    problem(f"{where}: FILL block {bi} extrudes {eb:.5g}/mm instead of {ea * flow:.5g}/mm")
        if not rewritten_meshes:
            continue
        # New infill must stay in the layer's infill area; old infill places must keep infill.
        new_fill = np.zeros((0, 2, 2))
        fill_b = extr_b & (mb["kind"] == FILL)
        if fill_b.any():
            new_fill = segments_of(mb, fill_b)
        areas = []
        # infill meshes live inside their host's infill area, even when the host printed no FILL itself
        for mesh in [x for x in pa.meshes if x != "NONMESH"]:
            g = mesh_layer(pa, mesh, width, 0.1 * width, 3.0 * width / 0.2)
            if not g.area.is_empty:
                areas.append(g.area)
        # where Cura's own infill ran (the pass prints Cura's lines where it cannot confirm an area)
        if fill_a.any():
            areas.append(multilinestring_of(list(segments_of(ma, fill_a))).buffer(width / 2, 2))
        from ..geometry import unary_union

        allowed = unary_union(areas).buffer(width) if areas else None
        if len(new_fill) and allowed is not None:
            pts = sample_segments(new_fill, width / 2)
            d = new_fill[:, 1] - new_fill[:, 0]
            n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / (width / 2)).astype(np.int64)) + 1
            w = np.repeat(np.hypot(d[:, 0], d[:, 1]) / n, n)
            inside = contains_xy(allowed, pts[:, 0], pts[:, 1])
            outside_len += float(w[~inside].sum())
            total_len += float(w.sum())
            res.new_infill_mm += float(np.hypot(d[:, 0], d[:, 1]).sum())
        old_fill = fill_a & np.isin(ma["mesh"], [pa.meshes.index(x) for x in rewritten_meshes])
        if old_fill.any():
            old_segs = segments_of(ma, old_fill)
            probe = sample_segments(old_segs, 2.0)
            covered_total += len(probe)
            if len(new_fill):
                tree = cKDTree(sample_segments(new_fill, width))
                dist, _ = tree.query(probe)
                radius = coverage_radius if coverage_radius is not None else 2.5 * width / min_density
                uncovered += int((dist > radius).sum())
            else:
                uncovered += len(probe)
    res.outside_fraction = outside_len / total_len if total_len > 0 else 0.0
    res.uncovered_fraction = uncovered / covered_total if covered_total else 0.0
    # The totals are always reported, whatever the per-layer cap dropped.
    if res.outside_fraction > 0.01:
        res.problems.append(f"{res.outside_fraction * 100:.2f} % of the new infill lies outside the infill area (limit 1 %)")
    if res.uncovered_fraction > 0.01:
        res.problems.append(f"{res.uncovered_fraction * 100:.2f} % of Cura's infill places have no new infill nearby (limit 1 %)")
    return res


def verify_files(original_path, processed_path, **kwargs) -> Verification:
    """`verify` for two G-code files (read whole; for tests and ``--verify``)."""
    with open(original_path, encoding="utf-8", newline="") as f:
        a = f.read()
    with open(processed_path, encoding="utf-8", newline="") as f:
        b = f.read()
    return verify([a], [b], **kwargs)
