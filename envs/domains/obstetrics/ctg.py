"""Cardiotocography: synthesise a fetal heart rate series from its features, and interpret a series.

`synthesise` writes a 0.5 Hz FHR series (one sample every 2 s) and the contraction windows from
a specification (baseline, variability amplitude, accelerations, decelerations placed relative
to contractions). `interpret` reads only the series and the contractions and applies the
NICHD 2008 definitions (Macones GA et al. Obstet Gynecol 2008;112:661-666):

* baseline: mean FHR outside accelerations/decelerations, rounded to 5 bpm;
* variability: median peak-to-trough amplitude of the baseline minutes: absent <= 2 bpm
  (undetectable), minimal 3-5, moderate 6-25, marked > 25;
* acceleration: >= 15 bpm above baseline for >= 15 s (>= 32 weeks; 10 bpm / 10 s before);
* deceleration: >= 15 bpm below baseline for >= 15 s; gradual (onset to nadir >= 30 s) or abrupt;
  gradual with nadir at the contraction peak = early, nadir after the peak = late; abrupt =
  variable; >= 2 min = prolonged; recurrent = with >= 50% of contractions;
* Category I: baseline 110-160, moderate variability, no late, variable or prolonged
  decelerations; Category III: absent variability with recurrent late or variable decelerations
  or bradycardia (or a sinusoidal pattern); Category II: everything else.
"""

from __future__ import annotations

import math
import random
from statistics import median

import numpy as np

STEP_S = 2  # seconds per sample


# -- synthesis -----------------------------------------------------------------------------------
def _bump(t: float, start: float, length: float) -> float:
    """Raised cosine 0..1..0 over [start, start + length]."""
    if t < start or t > start + length:
        return 0.0
    return 0.5 - 0.5 * math.cos(2 * math.pi * (t - start) / length)


def _decel_shape(t: float, onset: float, to_nadir: float, hold: float, recover: float) -> float:
    """0..1 depth profile: descent over to_nadir seconds, flat bottom, recovery."""
    if t < onset:
        return 0.0
    x = t - onset
    if x < to_nadir:
        return 0.5 - 0.5 * math.cos(math.pi * x / to_nadir)
    x -= to_nadir
    if x < hold:
        return 1.0
    x -= hold
    if x < recover:
        return 0.5 + 0.5 * math.cos(math.pi * x / recover)
    return 0.0


def synthesise(spec: dict, seed: int) -> dict:
    """Build {"fhr": [...], "contractions": [[start, peak, end], ...], "sample_interval_s": 2}.

    spec keys: minutes, baseline, variability_amplitude, contraction_interval_s (None: no
    contractions), accelerations (count), decelerations: list of {"type": early|late|variable|
    prolonged, "contraction": index or None, "depth": bpm, "duration_s": for prolonged}.
    """
    rng = random.Random(seed)
    total = spec["minutes"] * 60
    n = total // STEP_S
    contractions: list[list[int]] = []
    interval = spec.get("contraction_interval_s")
    if interval:
        t = rng.randint(40, 80)
        while t + 90 < total:
            length = rng.randint(60, 80)
            contractions.append([t, t + length // 2, t + length])
            t += interval + rng.randint(-15, 15)
    amp = spec["variability_amplitude"]
    comps = []
    for _ in range(3):
        cpm = rng.uniform(2.5, 5.0)
        comps.append((2 * math.pi * cpm / 60.0, rng.uniform(0, 2 * math.pi), rng.uniform(0.6, 1.0)))
    unit = [sum(w * math.sin(om * i * STEP_S + ph) for om, ph, w in comps) for i in range(n)]
    per_min = 60 // STEP_S
    # Scale so that the median peak-to-trough amplitude of the minutes equals the specified amplitude.
    measured = median(max(unit[m * per_min:(m + 1) * per_min]) - min(unit[m * per_min:(m + 1) * per_min])
                      for m in range(n // per_min))
    gain = amp / measured if measured else 0.0
    events: list[tuple[str, float, float]] = []  # (kind, start, end) for spacing accelerations
    decel_profiles = []
    for d in spec.get("decelerations", []):
        kind, depth = d["type"], d["depth"]
        if kind == "prolonged":
            onset = d.get("onset_s", total * 0.45)
            decel_profiles.append((onset, 20.0, d["duration_s"] - 50.0, 30.0, depth))
            events.append(("d", onset, onset + d["duration_s"]))
            continue
        c_start, c_peak, c_end = contractions[d["contraction"]]
        if kind == "early":
            to_nadir = rng.uniform(40, 55)
            onset = c_peak - to_nadir
            hold, recover = 4.0, rng.uniform(35, 45)
        elif kind == "late":
            to_nadir = rng.uniform(40, 55)
            lag = rng.uniform(28, 40)
            onset = c_peak + lag - to_nadir
            hold, recover = 4.0, rng.uniform(35, 45)
        else:  # variable: abrupt, timing unrelated to the peak
            to_nadir = rng.uniform(8, 14)
            onset = c_start + rng.uniform(0, 25)
            hold, recover = rng.uniform(10, 30), rng.uniform(10, 16)
        decel_profiles.append((onset, to_nadir, hold, recover, depth))
        events.append(("d", onset, onset + to_nadir + hold + recover))
    accel_profiles = []
    tries = 0
    while len(accel_profiles) < spec.get("accelerations", 0) and tries < 500:
        tries += 1
        length = rng.uniform(36, 50)
        start = rng.uniform(30, total - 90)
        busy = [(s - 40, e + 40) for _, s, e in events] + [(c[0] - 30, c[2] + 30) for c in contractions]
        if any(s < start + length and start < e for s, e in busy):
            continue
        accel_profiles.append((start, length, rng.uniform(22, 27)))
        events.append(("a", start, start + length))
    fhr = []
    for i in range(n):
        t = i * STEP_S
        var = unit[i] * gain
        dec = 0.0
        for onset, to_nadir, hold, recover, depth in decel_profiles:
            dec = max(dec, depth * _decel_shape(t, onset, to_nadir, hold, recover))
        acc = sum(h * _bump(t, s, length) for s, length, h in accel_profiles)
        scale = 0.3 if dec > 0 else 1.0
        fhr.append(int(round(spec["baseline"] + var * scale + acc - dec + rng.uniform(-0.4, 0.4))))
    return {"fhr": fhr, "contractions": contractions, "sample_interval_s": STEP_S, "minutes": spec["minutes"]}


# -- interpretation ------------------------------------------------------------------------------
def _runs(mask, min_len: int) -> list[tuple[int, int]]:
    """[start, end) index pairs of True runs at least min_len long."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_len]


def _smooth(values, k: int) -> np.ndarray:
    """Centred moving average over 2k+1 samples (shorter at the edges)."""
    v = np.asarray(values, dtype=float)
    c = np.concatenate(([0.0], np.cumsum(v)))
    idx = np.arange(len(v))
    lo, hi = np.maximum(0, idx - k), np.minimum(len(v), idx + k + 1)
    return (c[hi] - c[lo]) / (hi - lo)


def interpret(tracing: dict, gestational_age_weeks: float = 40.0) -> dict:
    arr = np.asarray(tracing["fhr"], dtype=float)
    fhr = arr.tolist()
    step = tracing.get("sample_interval_s", STEP_S)
    contractions = tracing.get("contractions", [])
    if len(fhr) < 10 * 60 // step:
        raise ValueError(f"tracing too short: {len(fhr) * step / 60:.1f} min (NICHD needs >= 10 min)")
    amp_up = 15 if gestational_age_weeks >= 32 else 10
    min_len = (15 if gestational_age_weeks >= 32 else 10) // step + 1
    # Baseline: iterate median -> exclude episodes -> mean.
    base = float(np.median(arr))
    sm = _smooth(arr, 2)
    for _ in range(3):
        episode = np.zeros(len(arr), dtype=bool)
        for a, b in _runs(arr >= base + amp_up, min_len) + _runs(arr <= base - 15, min_len):
            lo, hi = a, b
            while lo > 0 and abs(sm[lo - 1] - base) > 8:
                lo -= 1
            while hi < len(arr) and abs(sm[hi] - base) > 8:
                hi += 1
            episode[max(0, lo - 5):min(len(arr), hi + 5)] = True
        kept = arr[~episode]
        if len(kept) < 2 * 60 // step:
            kept = arr
        base = float(kept.mean())
    baseline = int(5 * round(base / 5))
    # Variability: median per-minute amplitude over minutes that are mostly baseline.
    per_min = 60 // step
    amps = []
    for m in range(len(arr) // per_min):
        seg = arr[m * per_min:(m + 1) * per_min][~episode[m * per_min:(m + 1) * per_min]]
        if len(seg) >= per_min * 0.8:
            amps.append(float(seg.max() - seg.min()))
    amplitude = median(amps) if amps else 0.0
    if amplitude <= 2:
        variability = "absent"
    elif amplitude <= 5:
        variability = "minimal"
    elif amplitude <= 25:
        variability = "moderate"
    else:
        variability = "marked"
    accelerations = len(_runs(arr >= baseline + amp_up, min_len))
    # Decelerations.
    smooth = sm.tolist()
    fine = _smooth(arr, 1).tolist()
    decels = []
    for a, b in _runs(arr <= baseline - 15, 15 // step + 1):
        nadir_i = min(range(a, b), key=lambda i: (smooth[i], i))
        depth = baseline - smooth[nadir_i]
        nadir_t = nadir_i * step
        # Onset to nadir from the slope of the descending limb: the fall from 25% to 75% of the
        # depth takes one third of the descent of a smooth (cosine-shaped) deceleration.
        k75 = nadir_i
        while k75 > 0 and fine[k75 - 1] <= baseline - 0.75 * depth:
            k75 -= 1
        k25 = k75
        while k25 > 0 and fine[k25 - 1] <= baseline - 0.25 * depth:
            k25 -= 1
        onset_to_nadir = 3.0 * (k75 - k25) * step
        lo, hi = a, b
        while lo > 0 and smooth[lo - 1] < baseline - 5:
            lo -= 1
        while hi < len(fhr) and smooth[hi] < baseline - 5:
            hi += 1
        duration = (hi - lo) * step
        contraction = None
        for k, (cs, cp, ce) in enumerate(contractions):
            if cs - 30 <= nadir_t <= ce + 60:
                contraction = k
                break
        if duration >= 120:
            kind = "prolonged"
        elif onset_to_nadir < 30:
            kind = "variable"
        elif contraction is not None:
            lag = nadir_t - contractions[contraction][1]
            kind = "late" if lag > 15 else "early"
        else:
            kind = "variable"
        decels.append({"type": kind, "nadir_s": nadir_t, "depth_bpm": round(depth), "duration_s": duration,
                       "onset_to_nadir_s": round(onset_to_nadir), "contraction": contraction})
    n_contr = len(contractions)
    minutes = len(fhr) * step / 60
    per10 = round(n_contr / minutes * 10, 1) if minutes else 0.0
    recurrent = {}
    for kind in ("early", "late", "variable"):
        with_c = {d["contraction"] for d in decels if d["type"] == kind and d["contraction"] is not None}
        recurrent[kind] = bool(n_contr) and len(with_c) >= 0.5 * n_contr
    has = {k: any(d["type"] == k for d in decels) for k in ("early", "late", "variable", "prolonged")}
    brady, tachy = baseline < 110, baseline > 160
    if variability == "absent" and (recurrent["late"] or recurrent["variable"] or brady):
        category = "Category III"
    elif 110 <= baseline <= 160 and variability == "moderate" and not (has["late"] or has["variable"] or has["prolonged"]):
        category = "Category I"
    else:
        category = "Category II"
    return {
        "baseline_bpm": baseline, "baseline_class": "bradycardia" if brady else "tachycardia" if tachy else "normal",
        "variability": variability, "variability_amplitude_bpm": round(amplitude, 1), "accelerations": accelerations,
        "decelerations": decels,
        "deceleration_summary": {k: sum(1 for d in decels if d["type"] == k) for k in ("early", "late", "variable", "prolonged")},
        "recurrent": recurrent, "contractions_per_10_min": per10, "tachysystole": per10 > 5,
        "category": category, "minutes_analysed": round(minutes, 1),
    }


def classify_spec(spec: dict) -> str:
    """The NICHD category a specification is designed to have (the generator's ground truth)."""
    amp = spec["variability_amplitude"]
    variability = "absent" if amp <= 2 else "minimal" if amp <= 5 else "moderate" if amp <= 25 else "marked"
    kinds = [d["type"] for d in spec.get("decelerations", [])]
    n_contr = spec.get("n_contractions", 0)
    rec = {k: n_contr > 0 and sum(1 for x in kinds if x == k) >= 0.5 * n_contr for k in ("late", "variable")}
    brady = spec["baseline"] < 110
    if variability == "absent" and (rec["late"] or rec["variable"] or brady):
        return "Category III"
    if 110 <= spec["baseline"] <= 160 and variability == "moderate" and not ({"late", "variable", "prolonged"} & set(kinds)):
        return "Category I"
    return "Category II"
