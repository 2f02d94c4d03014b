"""Image analysis computed from the pixels of a study image (no access to how it was made).

Chest radiograph: lung fields are the regions enclosed by the pleural outlines (4-connected
regions of pixels darker than the outline that do not reach the image border), holes filled.
Inside them, opacities (>= 100) are labelled: a component reaching the lowest rows of its lung
field is a pleural effusion; one with internal lucencies (air bronchograms, >= 5 px) or a very
irregular outline (solidity < 0.8) is consolidation; a round one is a nodule (< 30 mm) or a mass. Lucent
regions (<= 35) without lung markings are pneumothorax. The cardiothoracic ratio is the maximal
heart width (>= 172) over the maximal internal thoracic width (outer edges of the lung fields).

Chest CT slice: lungs are the dark (< 50) regions of the body, holes filled; nodules are
components >= 50 inside them larger than 3 mm equivalent diameter; the solid core is >= 105;
axes come from the second moments of the component (full axis = 4 sqrt(eigenvalue), corrected
for pixel size); type: solid (core >= 60% of the area), part-solid (a core of >= 6 px), or
ground-glass.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull

CROSS = ndimage.generate_binary_structure(2, 1)
SQUARE = ndimage.generate_binary_structure(2, 2)


def intensity_stats(img: np.ndarray, mask: np.ndarray | None = None) -> dict:
    vals = img[mask] if mask is not None else img.ravel()
    if vals.size == 0:
        return {"pixels": 0}
    p = np.percentile(vals, [5, 50, 95])
    return {"pixels": int(vals.size), "mean": round(float(vals.mean()), 1), "std": round(float(vals.std()), 1),
            "min": int(vals.min()), "p5": float(p[0]), "median": float(p[1]), "p95": float(p[2]), "max": int(vals.max())}


def _axes(ys: np.ndarray, xs: np.ndarray) -> tuple[float, float, float]:
    """(long, short) full axes in pixels from the second moments, and the orientation in degrees."""
    if len(ys) < 3:
        return float(len(ys)), float(len(ys)), 0.0
    cov = np.cov(np.vstack([xs, ys]).astype(float))
    vals, vecs = np.linalg.eigh(cov)
    vals = np.clip(vals - 1.0 / 12.0, 1e-6, None)
    long_, short = 4 * math.sqrt(vals[1]), 4 * math.sqrt(vals[0])
    angle = math.degrees(math.atan2(vecs[1, 1], vecs[0, 1]))
    return long_, short, angle


def _solidity(ys: np.ndarray, xs: np.ndarray) -> float:
    if len(ys) < 6:
        return 1.0
    pts = np.vstack([xs, ys]).T.astype(float)
    try:
        hull = ConvexHull(pts)
    except Exception:  # degenerate (a line)
        return 1.0
    # Pixel count over the area of the hull of the pixel centres grown by half a pixel all round.
    return float(len(ys) / (hull.volume + hull.area * 0.5 + math.pi * 0.25))


# -- chest radiograph ----------------------------------------------------------------------------
def _fill(mask: np.ndarray) -> np.ndarray:
    """binary_fill_holes on the bounding box only (same result, a fraction of the cost)."""
    out = np.zeros_like(mask)
    sl = ndimage.find_objects(mask.astype(np.int8))
    if sl and sl[0] is not None:
        out[sl[0]] = ndimage.binary_fill_holes(mask[sl[0]])
    return out


def _components(mask: np.ndarray, structure) -> list[tuple[tuple[slice, slice], np.ndarray]]:
    """(bounding-box slices, component mask within the box) for each connected component."""
    labels, n = ndimage.label(mask, structure=structure)
    out = []
    for i, sl in enumerate(ndimage.find_objects(labels), 1):
        if sl is not None:
            out.append((sl, labels[sl] == i))
    return out


def cxr_lung_fields(img: np.ndarray) -> dict[str, np.ndarray]:
    labels, n = ndimage.label(img < 137, structure=CROSS)
    border = set(np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])).tolist())
    fields: dict[str, np.ndarray] = {}
    objects = ndimage.find_objects(labels)
    comps = []
    for i, sl in enumerate(objects, 1):
        if sl is None or i in border:
            continue
        sub = labels[sl] == i
        if sub.sum() > 1500:
            comps.append((int(sub.sum()), sl, sub))
    comps.sort(key=lambda c: -c[0])
    for _, sl, sub in comps[:2]:
        mask = np.zeros(img.shape, dtype=bool)
        mask[sl] = ndimage.binary_fill_holes(sub)
        cx = (sl[1].start + sl[1].stop) / 2
        fields["right" if cx < img.shape[1] / 2 else "left"] = mask  # radiological convention
    if len(fields) != 2:
        raise ValueError(f"could not identify both lung fields (found {len(fields)}); is this a PA chest radiograph?")
    return fields


def analyze_cxr(img: np.ndarray, spacing_mm: float) -> dict:
    fields = cxr_lung_fields(img)
    findings = []
    lung_stats = {}
    for side, field in fields.items():
        rows = np.flatnonzero(field.any(axis=1))
        top, bottom = int(rows[0]), int(rows[-1])
        height = bottom - top + 1
        normal = field & (img >= 36) & (img < 100)
        lung_stats[side] = intensity_stats(img, normal)
        for sl, comp in _components(field & (img >= 100), SQUARE):
            area = int(comp.sum())
            if area < 12:
                continue
            filled = ndimage.binary_fill_holes(comp)
            holes = int(filled.sum() - area)
            ly, lx = np.nonzero(comp)
            fy, fx = np.nonzero(filled)
            oy, ox = sl[0].start, sl[1].start
            centroid_y = float(ly.mean()) + oy
            zone = ("upper", "middle", "lower")[min(2, int(3 * (centroid_y - top) / height))]
            eq_d = 2 * math.sqrt(len(fy) / math.pi) * spacing_mm
            base = {"side": side, "zone": zone, "area_mm2": round(float(len(fy)) * spacing_mm ** 2, 1),
                    "centroid_px": [round(float(lx.mean()) + ox, 1), round(centroid_y, 1)],
                    "mean_intensity": round(float(img[sl][comp].mean()), 1)}
            if ly.max() + oy >= bottom - 2:
                findings.append({"finding": "pleural effusion", **base,
                                 "height_mm": round(float(bottom - (ly.min() + oy) + 1) * spacing_mm, 1)})
                continue
            solidity = _solidity(fy, fx)
            if holes >= 5 or solidity < 0.8:
                findings.append({"finding": "consolidation", **base, "solidity": round(solidity, 3), "internal_lucencies_px": holes})
                continue
            long_px, short_px, _ = _axes(fy, fx)
            kind = "mass" if eq_d >= 30 else "nodule"
            findings.append({"finding": kind, **base, "diameter_mm": round(eq_d, 1),
                             "long_axis_mm": round(long_px * spacing_mm, 1), "short_axis_mm": round(short_px * spacing_mm, 1),
                             "solidity": round(solidity, 3)})
        # Lucency without lung markings: one pneumothorax per side (its pieces around the collapsed
        # lung are counted together).
        pieces = [(sl, c) for sl, c in _components(field & (img <= 35), SQUARE) if c.sum() >= 20]
        total = sum(int(c.sum()) for _, c in pieces)
        if total >= 60:
            cx_ = np.concatenate([np.nonzero(c)[1] + sl[1].start for sl, c in pieces])
            cy_ = np.concatenate([np.nonzero(c)[0] + sl[0].start for sl, c in pieces])
            lung_rows = np.flatnonzero(normal.any(axis=1))
            findings.append({"finding": "pneumothorax", "side": side, "zone": "apical/lateral",
                             "area_mm2": round(total * spacing_mm ** 2, 1),
                             "apical_distance_mm": round((int(lung_rows[0]) - top) * spacing_mm, 1) if len(lung_rows) else None,
                             "centroid_px": [round(float(cx_.mean()), 1), round(float(cy_.mean()), 1)]})
    heart = img >= 172
    any_row = heart.any(axis=1)
    if any_row.any():
        first = np.argmax(heart, axis=1)
        last = heart.shape[1] - 1 - np.argmax(heart[:, ::-1], axis=1)
        heart_w = int((last - first + 1)[any_row].max())
    else:
        heart_w = 0
    left_outer = int(np.flatnonzero(fields["left"].any(axis=0))[-1])
    right_outer = int(np.flatnonzero(fields["right"].any(axis=0))[0])
    thoracic = left_outer - right_outer + 1
    ctr = round(heart_w / thoracic, 3) if thoracic else None
    if ctr is not None and ctr > 0.5:
        findings.append({"finding": "cardiomegaly", "side": "central", "zone": "cardiac", "cardiothoracic_ratio": ctr})
    return {"findings": findings, "cardiothoracic_ratio": ctr, "heart_width_mm": round(heart_w * spacing_mm, 1),
            "thoracic_width_mm": round(thoracic * spacing_mm, 1), "lung_fields": {
                side: {"area_mm2": round(float(f.sum()) * spacing_mm ** 2, 1), "normal_parenchyma": lung_stats[side]}
                for side, f in fields.items()}}


# -- CT slice -----------------------------------------------------------------------------------
def ct_lungs(img: np.ndarray) -> dict[str, np.ndarray]:
    body = _fill(img > 60)
    comps = sorted(((int(c.sum()), sl, c) for sl, c in _components((img < 50) & body, CROSS) if c.sum() > 1500),
                   key=lambda t: -t[0])[:2]
    lungs = {}
    for _, sl, c in comps:
        mask = np.zeros(img.shape, dtype=bool)
        mask[sl] = ndimage.binary_fill_holes(c)
        lungs["right" if (sl[1].start + sl[1].stop) / 2 < img.shape[1] / 2 else "left"] = mask
    if len(lungs) != 2:
        raise ValueError(f"could not identify both lungs (found {len(lungs)}); is this an axial chest CT slice?")
    return lungs


def analyze_ct(img: np.ndarray, spacing_mm: float) -> dict:
    lungs = ct_lungs(img)
    nodules = []
    for side, lung in lungs.items():
        for sl, comp in _components(lung & (img >= 50), SQUARE):
            area = int(comp.sum())
            if area < 14:
                continue
            sub = img[sl]
            core = comp & (sub >= 105)
            core_area = int(core.sum())
            kind = "solid" if core_area >= 0.6 * area else "part_solid" if core_area >= 6 else "ground_glass"
            measure = comp & (sub >= 80) if kind == "solid" else comp & (sub >= 48)
            long_px, short_px, angle = _axes(*np.nonzero(measure))
            ys, xs = np.nonzero(comp)
            row = {"side": side, "type": kind, "long_axis_mm": round(long_px * spacing_mm, 1),
                   "short_axis_mm": round(short_px * spacing_mm, 1),
                   "mean_diameter_mm": round((long_px + short_px) / 2 * spacing_mm, 1),
                   "centroid_px": [round(float(xs.mean()) + sl[1].start, 1), round(float(ys.mean()) + sl[0].start, 1)],
                   "mean_intensity": round(float(sub[comp].mean()), 1)}
            if kind == "part_solid":
                cl, cs, _ = _axes(*np.nonzero(comp & (sub >= 103)))
                row["solid_component_mm"] = round((cl + cs) / 2 * spacing_mm, 1)
            nodules.append(row)
    nodules.sort(key=lambda r: -r["mean_diameter_mm"])
    for k, row in enumerate(nodules, 1):
        row["index"] = k
    return {"nodules": nodules, "nodule_count": len(nodules),
            "lungs": {side: {"area_mm2": round(float(m.sum()) * spacing_mm ** 2, 1),
                             "parenchyma": intensity_stats(img, m & (img < 50))} for side, m in lungs.items()}}
