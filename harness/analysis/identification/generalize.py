"""Surface fits of the diaphragm-specific parameters over filler fraction and diameter
(paper section 6.3, Figure 6).

The identified Em, K1, K2, C and m of the training samples (10/20/30 wt% x 30/45/60 mm)
are interpolated piecewise-cubically with C1 continuity (Clough-Tocher,
``scipy.interpolate.CloughTocher2DInterpolator``) to predict the parameters of an unseen
sample (the paper's 15 and 25 wt%, 45 mm).

Choice of the fitted quantities (documented because it matters): each parameter is
interpolated as log(value) over (log wt_pct, log diameter_mm), both coordinates scaled to
[0, 1] over the samples. Reasons:

* positivity: exp() of the interpolant can never give a negative mass, stiffness or
  coupling, however the cubic pieces over- or undershoot;
* scaling: these quantities follow power laws to first order (the magnetic coupling grows
  with the amount of filler, ~ wt% x area; plate stiffness falls with a power of the
  diameter; mass grows with area), which are linear in log-log coordinates, where the
  cubic pieces then only carry the smaller deviations. With the virtual rig's smooth
  parameter laws this predicts the unseen samples within about 0.3 %, against up to
  7 % for values and coordinates fitted linearly;
* scaling both coordinates to [0, 1] keeps the Clough-Tocher gradient estimate (which
  minimizes a curvature measure) independent of the units of wt% and mm.

A parameter with a value <= 0 at some sample (K1 may be 0) is fitted linearly instead.
Predictions are only made inside the convex hull of the samples (no extrapolation).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np
from scipy.interpolate import CloughTocher2DInterpolator
from scipy.spatial import Delaunay

from fmu_src.specs import Params
from harness.data.paramsjson import KEYS, params_to_json

__all__ = ["SurfaceFits", "fit_surfaces", "predict", "predict_arrays", "predict_params", "fits_to_json", "FIT_PARAMS",
           "GeneralizationError", "mean_coil", "predict_samples", "write_generalization"]

FIT_PARAMS = ("Em", "K1", "K2", "C", "m")


class GeneralizationError(ValueError):
    """A fit or a prediction that cannot be made (too few samples, outside the convex hull)."""


@dataclass
class SurfaceFits:
    """Interpolants of the diaphragm-specific parameters over (wt_pct, diameter_mm)."""
    wt_pct: np.ndarray            # sample filler fractions [wt%]
    diameter_mm: np.ndarray       # sample diameters [mm]
    values: dict                  # name -> values at the samples (SI units)
    log_values: dict              # name -> bool (fitted as log(value))
    log_coords: bool
    samples: list = field(default_factory=list)   # sample ids (if known)
    _lo: np.ndarray = field(default=None, repr=False)
    _span: np.ndarray = field(default=None, repr=False)
    _tri: Delaunay = field(default=None, repr=False)
    _interp: dict = field(default_factory=dict, repr=False)

    def _coords(self, wt_pct, diameter_mm) -> np.ndarray:
        """Scaled fit coordinates of (wt_pct [wt%], diameter_mm [mm])."""
        w = np.atleast_1d(np.asarray(wt_pct, dtype=float))
        d = np.atleast_1d(np.asarray(diameter_mm, dtype=float))
        if np.any(w <= 0) or np.any(d <= 0):
            raise GeneralizationError(f"wt_pct and diameter_mm must be > 0, got {wt_pct!r}, {diameter_mm!r}")
        P = np.column_stack(np.broadcast_arrays(w, d)).astype(float)
        if self.log_coords:
            P = np.log(P)
        return (P - self._lo) / self._span

    def hull_text(self) -> str:
        """The fitted samples' ranges of wt_pct [wt%] and diameter_mm [mm], for messages."""
        return (f"wt_pct {self.wt_pct.min():g}-{self.wt_pct.max():g}, "
                f"diameter_mm {self.diameter_mm.min():g}-{self.diameter_mm.max():g} "
                f"(samples at {sorted(set(zip(self.wt_pct.tolist(), self.diameter_mm.tolist())))})")


def _entries(samples) -> list:
    """(id, wt_pct, diameter_mm, {name: value}) from the accepted inputs."""
    out = []
    if isinstance(samples, Mapping):
        items = list(samples.items())
    else:
        items = [(None, s) for s in samples]
    for sid, s in items:
        if hasattr(s, "params") and hasattr(s, "wt_pct"):            # SampleIdentification
            out.append((sid or getattr(s, "sample", None), float(s.wt_pct), float(s.diameter_mm),
                        {n: float(getattr(s.params, n)) for n in FIT_PARAMS}))
        elif isinstance(s, (tuple, list)) and len(s) == 3:
            w, d, p = s
            vals = {n: float(p[n] if isinstance(p, Mapping) else getattr(p, n)) for n in FIT_PARAMS}
            out.append((sid, float(w), float(d), vals))
        else:
            raise TypeError("samples must be {id: SampleIdentification} or an iterable of "
                            "(wt_pct, diameter_mm, Params or {name: value})")
    return out


def fit_surfaces(samples, log_values: bool = True, log_coords: bool = True) -> SurfaceFits:
    """Fit C1 piecewise-cubic surfaces of Em, K1, K2, C, m over (wt_pct, diameter_mm).

    samples: {id: SampleIdentification} (e.g. from :func:`harness.analysis.identification.identify.identify_dataset`)
    or an iterable of (wt_pct [wt%], diameter_mm [mm], Params or {name: SI value}).
    Needs at least 3 samples not on one line. See the module docstring for the choice
    of log values and log coordinates.
    """
    ent = _entries(samples)
    if len(ent) < 3:
        raise GeneralizationError(f"need at least 3 samples for a surface fit, got {len(ent)}")
    w = np.array([e[1] for e in ent])
    d = np.array([e[2] for e in ent])
    keys = list(zip(w.tolist(), d.tolist()))
    if len(set(keys)) != len(keys):
        raise GeneralizationError(f"two samples share (wt_pct, diameter_mm): {keys}")
    for n in FIT_PARAMS:
        vals = np.array([e[3][n] for e in ent])
        if not np.all(np.isfinite(vals)):
            raise GeneralizationError(f"parameter {n} has non-finite values: {vals.tolist()}")
    P = np.column_stack([w, d])
    if log_coords:
        if np.any(P <= 0):
            raise GeneralizationError("log coordinates need wt_pct > 0 and diameter_mm > 0")
        P = np.log(P)
    lo = P.min(axis=0)
    span = P.max(axis=0) - lo
    if np.any(span == 0):
        raise GeneralizationError("the samples do not span a surface (all share one wt_pct or one diameter)")
    Pn = (P - lo) / span
    try:
        tri = Delaunay(Pn)
    except Exception as exc:  # QhullError: collinear points
        raise GeneralizationError(f"the samples do not span a surface: {exc}") from None
    fits = SurfaceFits(wt_pct=w, diameter_mm=d, values={}, log_values={}, log_coords=log_coords,
                       samples=[e[0] for e in ent], _lo=lo, _span=span, _tri=tri)
    for n in FIT_PARAMS:
        vals = np.array([e[3][n] for e in ent])
        use_log = bool(log_values and np.all(vals > 0))
        fits.values[n] = vals
        fits.log_values[n] = use_log
        fits._interp[n] = CloughTocher2DInterpolator(tri, np.log(vals) if use_log else vals)
    return fits


def predict(fits: SurfaceFits, wt_pct: float, diameter_mm: float) -> dict:
    """Predicted {name: value} (SI) of Em, K1, K2, C, m at (wt_pct [wt%], diameter_mm [mm]).

    Raises :class:`GeneralizationError` outside the convex hull of the fitted samples.
    """
    q = fits._coords(wt_pct, diameter_mm)
    inside = fits._tri.find_simplex(q, tol=1e-9) >= 0
    if not np.all(inside):
        raise GeneralizationError(f"(wt_pct={wt_pct}, diameter_mm={diameter_mm}) is outside the convex hull of "
                                  f"the identified samples ({fits.hull_text()}); the surfaces do not extrapolate")
    out = {}
    for n in FIT_PARAMS:
        v = float(fits._interp[n](q)[0])
        if not math.isfinite(v):
            raise GeneralizationError(f"(wt_pct={wt_pct}, diameter_mm={diameter_mm}) is outside the convex hull "
                                      f"of the identified samples ({fits.hull_text()})")
        out[n] = math.exp(v) if fits.log_values[n] else v
    return out


def predict_arrays(fits: SurfaceFits, wt_pct, diameter_mm) -> dict:
    """Vectorized :func:`predict`: {name: array} (SI) of Em, K1, K2, C, m at the points (wt_pct [wt%],
    diameter_mm [mm]) (broadcast arrays); NaN at the points outside the convex hull of the fitted samples."""
    shape = np.broadcast(np.asarray(wt_pct, dtype=float), np.asarray(diameter_mm, dtype=float)).shape
    q = fits._coords(wt_pct, diameter_mm)
    inside = fits._tri.find_simplex(q, tol=1e-9) >= 0
    out = {}
    for n in FIT_PARAMS:
        v = np.where(inside, np.asarray(fits._interp[n](q), dtype=float).reshape(-1), np.nan)
        out[n] = (np.exp(v) if fits.log_values[n] else v).reshape(shape)
    return out


def predict_params(fits: SurfaceFits, wt_pct: float, diameter_mm: float, coil) -> Params:
    """Model parameters of an unseen sample: surfaces for Em, K1, K2, C, m; coil from ``coil``.

    coil: a Params (or anything with attributes) or a mapping providing a [m], kB [T/A],
    R [Ohm] and L [H] (e.g. the parameters identified for one of the training samples).
    D = diameter_mm / 1000. r0 stays at its default (it is set per test).
    """
    vals = predict(fits, wt_pct, diameter_mm)

    def get(name):
        if isinstance(coil, Mapping):
            if name not in coil:
                raise KeyError(f"coil: missing {name!r} (need a [m], kB [T/A], R [Ohm], L [H])")
            return float(coil[name])
        return float(getattr(coil, name))

    return Params(a=get("a"), kB=get("kB"), R=get("R"), L=get("L"), D=float(diameter_mm) / 1000.0,
                  **vals).validated()


def fits_to_json(fits: SurfaceFits, predictions: dict | None = None) -> dict:
    """The fitted nodes (and optional predictions {id: Params}) with units in the keys."""
    nodes = []
    for i in range(fits.wt_pct.size):
        row = {"sample": fits.samples[i] if i < len(fits.samples) else None,
               "wt_pct": float(fits.wt_pct[i]), "diameter_mm": float(fits.diameter_mm[i])}
        row.update({KEYS[n]: float(fits.values[n][i]) for n in FIT_PARAMS})
        nodes.append(row)
    out = {"method": "scipy.interpolate.CloughTocher2DInterpolator (C1 piecewise cubic)",
           "coordinates": "log(wt_pct), log(diameter_mm) scaled to [0, 1]" if fits.log_coords
           else "wt_pct, diameter_mm scaled to [0, 1]",
           "fitted_as_log": {n: bool(fits.log_values[n]) for n in FIT_PARAMS},
           "nodes": nodes}
    if predictions:
        out["predictions"] = {
            sid: {KEYS["D"]: p.D, **{KEYS[n]: float(getattr(p, n)) for n in FIT_PARAMS}}
            for sid, p in predictions.items()}
    return out


def mean_coil(results) -> dict:
    """The electromagnet's parameters averaged over identified samples: {a, kB, R, L} (SI).

    results: {id: SampleIdentification} (or an iterable of them). All samples sit in front
    of the same coil, so the mean of the per-sample identifications is its best estimate.
    """
    rs = list(results.values()) if isinstance(results, Mapping) else list(results)
    if not rs:
        raise GeneralizationError("no identified samples to take the coil parameters from")
    return {n: float(np.mean([getattr(r.params, n) for r in rs])) for n in ("a", "kB", "R", "L")}


def predict_samples(fits: SurfaceFits, samples, coil) -> tuple[dict, dict]:
    """Predicted Params for samples [(id, wt_pct, diameter_mm)]; returns ({id: Params}, {id: reason skipped})."""
    preds, skipped = {}, {}
    for sid, w, d in samples:
        try:
            preds[sid] = predict_params(fits, w, d, coil)
        except GeneralizationError as e:
            skipped[sid] = str(e)
    return preds, skipped


def write_generalization(fits: SurfaceFits, predictions: dict, out_dir, skipped: dict | None = None,
                         skipped_incomplete: dict | None = None) -> Path:
    """Write ``generalization.json``: surface nodes and, under "samples", the predicted
    parameters of unseen samples in the layout of identification.json ({id: {"parameters":
    {"R_Ohm": ..., ...}}}), so that the protocol runner can read it with ``--params``;
    "skipped": {id: why no prediction}; "skipped_samples": {id: why the sample was left out of
    the identification (incomplete data)}. Returns the path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    data = {"format": "mpc-actuator-generalization/1",
            "surfaces": fits_to_json(fits),
            "samples": {sid: {"parameters": params_to_json(p, effects=False)}
                        for sid, p in predictions.items()},
            "skipped": dict(skipped or {}),
            "skipped_samples": dict(skipped_incomplete or {})}
    path = out_dir / "generalization.json"
    path.write_text(json.dumps(data, indent=2) + "\n")
    return path
