"""Render synthetic chest radiographs and chest CT slices from a findings specification.

Images are 256 x 256 8-bit grayscale in radiological convention (the patient's right on the
image left). The anatomy (body, lungs with a pleural outline, mediastinum, heart, vessels) varies
with the seed; findings are drawn into it: nodules and masses (solid discs), consolidation
(lobulated opacity with air bronchograms), pleural effusion (dependent opacity with a meniscus),
pneumothorax (lucent rim without lung markings and a visceral pleural line), cardiomegaly (heart
width), and on CT solid, ground-glass and part-solid nodules of given axes and orientation.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

SIZE = 256
CXR_SPACING_MM = 1.4
CT_SPACING_MM = 0.7


def _grid() -> tuple[np.ndarray, np.ndarray]:
    return np.mgrid[0:SIZE, 0:SIZE].astype(float)


def _ellipse(yy, xx, cy, cx, ry, rx, angle: float = 0.0) -> np.ndarray:
    """Soft-edged (1 px) ellipse coverage in [0, 1]."""
    c, s = math.cos(angle), math.sin(angle)
    dy, dx = yy - cy, xx - cx
    u, v = dx * c + dy * s, -dx * s + dy * c
    r = np.sqrt((u / rx) ** 2 + (v / ry) ** 2)
    edge = 1.0 / max(min(rx, ry), 1.0)
    return np.clip((1.0 - r) / edge + 0.5, 0.0, 1.0)


def _texture(rng: np.random.Generator, sigma: float, amplitude: float) -> np.ndarray:
    noise = ndimage.gaussian_filter(rng.normal(0, 1, (SIZE, SIZE)), sigma)
    return noise / (noise.std() + 1e-9) * amplitude


# -- chest radiograph ----------------------------------------------------------------------------
def cxr_anatomy(seed: int, ctr: float) -> dict:
    """Geometry of the thorax for a cardiothoracic ratio `ctr`: lung masks, heart ellipse, landmarks."""
    rng = np.random.default_rng(seed)
    yy, xx = _grid()
    x_r, x_l = 40 + int(rng.integers(-3, 4)), 216 + int(rng.integers(-3, 4))
    mid = 128 + int(rng.integers(-2, 3))
    top, bottom = 46 + int(rng.integers(-3, 4)), 202 + int(rng.integers(-3, 4))
    heart_w = ctr * (x_l - x_r + 1)
    heart = {"cx": float(mid + 0.12 * heart_w), "cy": float(bottom - 36), "rx": float(heart_w / 2), "ry": 40.0}
    hy = np.clip(1 - ((yy[:, 0] - heart["cy"]) / heart["ry"]) ** 2, 0, None)
    heart_half = heart["rx"] * np.sqrt(hy)  # heart half-width per row (0 outside the heart rows)
    masks = {}
    for side in ("right", "left"):
        outer = x_r if side == "right" else x_l
        medial_top = mid - 12 if side == "right" else mid + 12
        width = abs(medial_top - outer) / 2
        cx = (outer + medial_top) / 2
        base = bottom + (4 if side == "left" else 0)
        t = np.clip((yy - top) / (base - top), 0, 1)
        half = width * (0.42 + 0.58 * np.sqrt(t))
        dome = base - 12 * (1 - ((xx - cx) / width) ** 2)
        m = (yy >= top) & (yy <= dome) & (np.abs(xx - cx) <= half)
        # Apex rounding: the top 14 rows narrow to a rounded cap.
        m &= ~((yy < top + 14) & (((xx - cx) / (half + 1e-9)) ** 2 + ((yy - top - 14) / 14.0) ** 2 > 1))
        if side == "right":
            m &= xx <= np.where(hy[:, None] > 0, heart["cx"] - heart_half[:, None] - 5, medial_top)
        else:
            m &= xx >= np.where(hy[:, None] > 0, heart["cx"] + heart_half[:, None] + 5, medial_top)
        masks[side] = m
    return {"masks": masks, "heart": heart, "mid": float(mid), "top": float(top), "bottom": float(bottom),
            "outer_right": float(x_r), "outer_left": float(x_l)}


def render_cxr(spec: dict, seed: int) -> tuple[np.ndarray, dict]:
    """spec: {"ctr": float, "findings": [ {type, side, zone, ...} ]} -> (image, anatomy)."""
    rng = np.random.default_rng(seed)
    anatomy = cxr_anatomy(seed, spec.get("ctr", 0.45))
    yy, xx = _grid()
    img = np.full((SIZE, SIZE), 8.0)
    body = np.zeros((SIZE, SIZE), dtype=bool)
    body[22:, 16:240] = True
    body &= ~((yy < 70) & ((np.abs(xx - 128) - 64) ** 2 + (yy - 70) ** 2 > 48 ** 2) & (np.abs(xx - 128) > 64))
    body = ndimage.gaussian_filter(body.astype(float), 1.0)
    img = img * (1 - body) + (118 + 0.05 * (yy - 22)) * body
    img[:, 116:140] = np.maximum(img[:, 116:140], 160 * (body[:, 116:140] > 0.5))
    for k, y0 in enumerate(range(36, 50, 10)):  # clavicles, above the apices
        band = (np.abs(yy - (y0 + 0.0025 * (xx - 128) ** 2 - 8)) < 2.5) & (np.abs(xx - 128) > 20) & (body > 0.5)
        img[band & ~anatomy["masks"]["right"] & ~anatomy["masks"]["left"]] = 160
    tex = _texture(rng, 1.6, 5.0)
    ribs = np.zeros((SIZE, SIZE))
    for y0 in range(56, 200, 19):
        ribs = np.maximum(ribs, (np.abs(yy - (y0 + 0.0035 * (xx - 128) ** 2 - 10)) < 2.2).astype(float))
    ribs = ndimage.gaussian_filter(ribs, 0.8) * 10
    lungs = {}
    for side in ("right", "left"):
        m = anatomy["masks"][side]
        cov = ndimage.gaussian_filter(m.astype(float), 0.6) * m
        lungs[side] = m
        img = img * (1 - cov) + (60 + tex + ribs) * cov
        ring = ndimage.binary_dilation(m, structure=ndimage.generate_binary_structure(2, 1), iterations=2) & ~m & (body > 0.5)
        img[ring] = 144
    h = anatomy["heart"]
    heart = _ellipse(yy, xx, h["cy"], h["cx"], h["ry"], h["rx"])
    img = img * (1 - heart) + 182 * heart
    for f in spec.get("findings", []):
        inside = lungs[f["side"]]
        if f["type"] in ("nodule", "mass"):
            r = f["diameter_mm"] / 2 / CXR_SPACING_MM
            disc = _ellipse(yy, xx, f["cy"], f["cx"], r, r)
            img = img * (1 - disc) + 150 * disc
        elif f["type"] == "consolidation":
            blob = np.zeros((SIZE, SIZE))
            for k in range(7):
                ang = 2 * math.pi * k / 7 + rng.uniform(0, 0.6)
                d = rng.uniform(3, 9)
                blob = np.maximum(blob, _ellipse(yy, xx, f["cy"] + d * math.sin(ang), f["cx"] + d * math.cos(ang),
                                                 rng.uniform(6, 10), rng.uniform(6, 10)))
            blob = blob * inside
            img = img * (1 - blob) + (122 + tex * 0.6) * blob
            for k in range(2):  # air bronchograms
                ang = rng.uniform(0, math.pi)
                length = rng.uniform(9, 14)
                for t in np.linspace(-length / 2, length / 2, 40):
                    y, x = int(round(f["cy"] + t * math.sin(ang) + 2 * k)), int(round(f["cx"] + t * math.cos(ang)))
                    if inside[y, x] and blob[y, x] > 0.9:
                        img[y, x] = 60
        elif f["type"] == "pleural effusion":
            ys, xs = np.nonzero(inside)
            top, bottom = ys.min(), ys.max()
            level = top + (bottom - top) * f["level_fraction"]
            lateral = xs.min() if f["side"] == "right" else xs.max()
            width = xs.max() - xs.min()
            meniscus = level - 14 * np.exp(-np.abs(xx - lateral) / (0.35 * width))
            img[(yy > meniscus) & inside] = 128
        elif f["type"] == "pneumothorax":
            depth = f["depth_px"]
            ys, xs = np.nonzero(inside)
            cx = xs.mean()
            shift = depth * 0.5 if f["side"] == "right" else -depth * 0.5
            collapsed = ndimage.shift(ndimage.binary_erosion(inside, iterations=int(depth * 0.55)).astype(float),
                                      (depth * 0.45, shift), order=0) > 0.5
            collapsed &= inside
            air = inside & ~collapsed
            img[air] = 12
            edge = collapsed & ~ndimage.binary_erosion(collapsed)
            img[edge] = 95
    img = img + rng.normal(0, 1.2, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8), anatomy


# -- CT slice -----------------------------------------------------------------------------------
def ct_anatomy(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    return {"lungs": {"right": {"cx": 66.0 + rng.integers(-2, 3), "cy": 118.0 + rng.integers(-3, 4), "rx": 34.0, "ry": 64.0},
                      "left": {"cx": 190.0 + rng.integers(-2, 3), "cy": 120.0 + rng.integers(-3, 4), "rx": 33.0, "ry": 62.0}},
            "vessels": int(rng.integers(25, 40))}


def render_ct(spec: dict, seed: int) -> tuple[np.ndarray, dict]:
    """spec: {"nodules": [{side, cy, cx, long_mm, short_mm, angle, type}]} -> (image, anatomy). Same seed, same anatomy."""
    rng = np.random.default_rng(seed)
    anatomy = ct_anatomy(seed)
    yy, xx = _grid()
    img = np.full((SIZE, SIZE), 4.0)
    body = _ellipse(yy, xx, 124, 128, 108, 124)
    img = img * (1 - body) + 128 * body
    for side in ("right", "left"):
        g = anatomy["lungs"][side]
        cov = _ellipse(yy, xx, g["cy"], g["cx"], g["ry"], g["rx"])
        img = img * (1 - cov) + 24 * cov
        for _ in range(anatomy["vessels"]):
            a, r = rng.uniform(0, 2 * math.pi), math.sqrt(rng.uniform(0, 0.8))
            vy, vx = g["cy"] + r * g["ry"] * math.sin(a), g["cx"] + r * g["rx"] * math.cos(a)
            vr = rng.uniform(0.6, 1.1)
            # Vessels never touch a nodule (same random draws with or without nodules, so a prior
            # and a current image of one patient share their anatomy).
            if any(math.hypot(vy - n["cy"], vx - n["cx"]) < n["long_mm"] / 2 / CT_SPACING_MM + 4 for n in spec.get("nodules", [])
                   + spec.get("keep_clear", [])):
                continue
            ves = _ellipse(yy, xx, vy, vx, vr, vr) * cov
            img = img * (1 - ves) + 95 * ves
    spine = _ellipse(yy, xx, 212, 128, 14, 14)
    img = img * (1 - spine) + 220 * spine
    heart = _ellipse(yy, xx, 118, 128, 44, 24)
    img = img * (1 - heart) + 140 * heart
    aorta = _ellipse(yy, xx, 170, 140, 9, 9)
    img = img * (1 - aorta) + 150 * aorta
    for k in range(18):  # ribs around the chest wall
        a = 2 * math.pi * k / 18
        rib = _ellipse(yy, xx, 124 + 100 * math.sin(a), 128 + 116 * math.cos(a), 3.5, 6)
        img = img * (1 - rib) + 210 * rib
    for n in spec.get("nodules", []):
        a, b = n["long_mm"] / 2 / CT_SPACING_MM, n["short_mm"] / 2 / CT_SPACING_MM
        cov = _ellipse(yy, xx, n["cy"], n["cx"], b, a, n["angle"])
        if n["type"] == "solid":
            img = img * (1 - cov) + 135 * cov
        elif n["type"] == "ground_glass":
            img = img * (1 - cov) + 72 * cov
        else:  # part-solid: ground-glass halo with a solid core of solid_mm
            img = img * (1 - cov) + 72 * cov
            c = n["solid_mm"] / 2 / CT_SPACING_MM
            core = _ellipse(yy, xx, n["cy"], n["cx"], c, c)
            img = img * (1 - core) + 135 * core
    img = img + rng.normal(0, 1.5, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8), anatomy
