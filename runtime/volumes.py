"""Reading and evaluating the volume AO models ``neuralao volumes`` bakes (Sloan et al. 2013, section 2.3).

The VOLUMES.json document (format ``neuralao-volumes`` v1, :func:`to_json` / :func:`from_json`), its
dataclasses (regions, edges, per-region models, the bake's settings) and the model of eq. 4
(:func:`design`, :func:`model_at`): what a consumer needs to evaluate the models without the baker
(:mod:`neuralao.pipeline.bakes.volumes`, which traces and fits them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from neuralao.runtime.foundation import sh
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.foundation.settings import from_dict, settings_to_dict

FORMAT = "neuralao-volumes"
VERSION = 1
TERMS = ("mean", "+x", "-x", "+y", "-y", "+z", "-z")
DISTANCES = ("short", "long")
# The keys :func:`to_json` writes: a file holding another is refused (a misspelt key would be ignored).
FILE_KEYS = (
    "format",
    "version",
    "method",
    "scene",
    "settings",
    "half_distances",
    "distances",
    "blend",
    "sh",
    "terms",
    "model",
    "lookup",
    "regions",
    "edges",
    "stats",
)
REGION_KEYS = (
    "name",
    "min",
    "max",
    "centre",
    "centre_choice",
    "valid_samples",
    "fit_rmse",
    "fallback",
    "coefficients",
)
EDGE_KEYS = ("regions", "area", "centre")


@dataclass
class VolumeSettings:
    # Samples per axis per region (Sloan et al.: 8 x 8 x 8).
    samples: int = 8
    # Spherical directions per sample (Sloan et al.: 1024), uniform over the whole sphere.
    directions: int = 1024
    # The two obscurance half distances (short, long) as fractions of the level's diagonal.
    half_distances_rel: tuple[float, float] = (0.05, 0.5)
    # The same in scene units; overrides half_distances_rel when set.
    half_distances: tuple[float, float] | None = None
    # Longest ray as a fraction of the diagonal: past every surface of the level ("unbounded").
    max_distance_rel: float = 4.0
    # Weight of the long distance in the blended AO of probes and GLSL (Sloan et al.: 97% long).
    blend: float = 0.97
    # Back-face rule over the sphere: a sample seeing more back faces than this is invalid.
    backface_threshold: float = 0.25
    # Weight of the boundary agreement term of the regularisation (0 disables it). With 3 x 3 agreement
    # points, 0.25 halves the popping over boundary faces for +21% RMSE (README, bench_volumes).
    beta: float = 0.25
    # Block-coordinate-descent sweeps of the regularisation.
    iterations: int = 8
    # Regularisation: agreement points per shared face, a k x k grid. 1 = the face centre b_ij (the
    # paper): it zeroes the jump at the centre but not across the face (measured), hence 3.
    boundary_grid: int = 3
    # Free-space regions: grid cells along the level's longest axis.
    grid: int = 16
    # Free-space regions: at most this many cells along any axis of one region.
    max_region_cells: int = 4
    # Free-space regions: axes thinner than this many cells are padded on both sides to it, so an open
    # level (terrain a few cells high) gets free space above its ground.
    min_cells: int = 4
    # Free-space regions: rays per cell centre for the inside-geometry test (back-face rule).
    cell_rays: int = 64
    # Seed of the per-sample direction jitter; the same seed gives identical models.
    seed: int = 0
    # Tracing threads (results do not depend on it).
    workers: int = 2


@dataclass(frozen=True)
class Region:
    """An axis-aligned box: lo (3,) and hi (3,) float64 corners, scene units."""

    name: str
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    @property
    def centre(self) -> np.ndarray:
        return (np.asarray(self.lo) + np.asarray(self.hi)) / 2.0

    @property
    def size(self) -> np.ndarray:
        return np.asarray(self.hi) - np.asarray(self.lo)


@dataclass(frozen=True)
class Edge:
    """Regions i < j share a boundary of ``area`` (scene units^2) centred at ``centre`` (3,)."""

    i: int
    j: int
    area: float
    centre: tuple[float, float, float]


@dataclass
class RegionModel:
    """Eq. 4 for one region: centre (3,) float64, coefficients (7, 2, 9) float64 (term, distance, SH).

    Coefficients are AO-space SH (clamped cosine applied): AO_d(n) = sum_j coefficients[., d, j] Y_j(n).
    """

    centre: np.ndarray
    coefficients: np.ndarray
    centre_choice: str = "centroid"  # "centroid" | "box" | "fallback"
    valid_samples: int = 0
    fit_rmse: float = 0.0  # RMS residual of the fit over valid samples, AO over every normal
    fallback: str | None = None  # None | "neighbours" | "open"


@dataclass
class Volumes:
    """Everything ``neuralao volumes`` writes (see :func:`to_json`)."""

    regions: list[Region]
    edges: list[Edge]
    models: list[RegionModel]
    half_distances: tuple[float, float]
    blend: float
    settings: VolumeSettings
    scene: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)


def check_regions(regions: list[Region], what: str = "regions") -> None:
    """One-line errors for an empty list, non-finite corners and degenerate (extent <= 0) boxes."""
    if not regions:
        raise NeuralaoError(f"{what}: no regions")
    for k, r in enumerate(regions):
        lo, hi = np.asarray(r.lo, np.float64), np.asarray(r.hi, np.float64)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
            raise NeuralaoError(f"{what}: region {k} ({r.name}) needs finite 3-vectors min and max")
        if not (hi > lo).all():
            raise NeuralaoError(
                f"{what}: region {k} ({r.name}) is degenerate: max must exceed min on every axis, "
                f"got min {lo.tolist()} max {hi.tolist()}"
            )


def design(points: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(n, 7) float64 rows [1, (p-c)_x+, (p-c)_x-, (p-c)_y+, (p-c)_y-, (p-c)_z+, (p-c)_z-] of eq. 4:
    the +axis column holds (p - c)_i where it is >= 0 (else 0), the -axis column where it is < 0."""
    d = np.atleast_2d(np.asarray(points, np.float64)) - np.asarray(centre, np.float64)
    pos = np.where(d >= 0.0, d, 0.0)
    neg = np.where(d < 0.0, d, 0.0)
    return np.column_stack(
        [np.ones(len(d)), pos[:, 0], neg[:, 0], pos[:, 1], neg[:, 1], pos[:, 2], neg[:, 2]]
    )


def model_at(model: RegionModel, points: np.ndarray) -> np.ndarray:
    """AO-space SH of the model at points: (n, 3) -> (n, 2, 9) float64."""
    return np.einsum("nt,tdj->ndj", design(points, model.centre), model.coefficients)


def to_json(vol: Volumes) -> dict:
    """The self-describing VOLUMES.json document (format ``neuralao-volumes`` v1)."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "method": "Sloan et al. 2013 section 2.3: per-region centre + constant + 6 directional derivatives",
        "scene": vol.scene,
        "settings": settings_to_dict(vol.settings),
        "half_distances": list(vol.half_distances),
        "distances": list(DISTANCES),
        "blend": vol.blend,
        "sh": {
            "count": sh.QUADRATIC,
            "basis": "real SH, order Y00, Y1-1, Y10, Y11, Y2-2, Y2-1, Y20, Y21, Y22 "
            "(runtime/foundation/sh.py)",
            "space": "AO: clamped cosine applied, AO_d(n) = sum_j f_dj Y_j(n) for a unit normal n",
        },
        "terms": list(TERMS),
        "model": "f(p) = v_mean + sum_i (p - c)_i v[2i + s_i], s_i = 0 if (p - c)_i >= 0 else 1",
        "lookup": "first region whose box holds p; outside every box: the nearest box",
        "regions": [
            {
                "name": r.name,
                "min": list(r.lo),
                "max": list(r.hi),
                "centre": m.centre.tolist(),
                "centre_choice": m.centre_choice,
                "valid_samples": m.valid_samples,
                "fit_rmse": m.fit_rmse,
                "fallback": m.fallback,
                "coefficients": m.coefficients.tolist(),
            }
            for r, m in zip(vol.regions, vol.models, strict=True)
        ],
        "edges": [{"regions": [e.i, e.j], "area": e.area, "centre": list(e.centre)} for e in vol.edges],
        "stats": vol.stats,
    }


def from_json(data: dict, what: str = "volumes") -> Volumes:
    """Inverse of :func:`to_json`; a wrong format or a malformed region is a one-line error."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise NeuralaoError(f"{what} is not a {FORMAT} file")
    if data.get("version") != VERSION:
        raise NeuralaoError(f"{what}: unsupported version {data.get('version')!r} (expected {VERSION})")
    _known_keys(data, FILE_KEYS, what, "key")
    for k, r in enumerate(data.get("regions", []) if isinstance(data.get("regions"), list) else []):
        if isinstance(r, dict):
            _known_keys(r, REGION_KEYS, what, f"key of region {k}")
    for k, e in enumerate(data.get("edges", []) if isinstance(data.get("edges"), list) else []):
        if isinstance(e, dict):
            _known_keys(e, EDGE_KEYS, what, f"key of edge {k}")
    try:
        settings = from_dict(VolumeSettings, data["settings"])
        regions, models = [], []
        for k, r in enumerate(data["regions"]):
            regions.append(Region(str(r["name"]), tuple(map(float, r["min"])), tuple(map(float, r["max"]))))
            coeffs = np.asarray(r["coefficients"], dtype=np.float64)
            centre = np.asarray(r["centre"], dtype=np.float64)
            if coeffs.shape != (7, 2, sh.QUADRATIC) or centre.shape != (3,):
                raise NeuralaoError(
                    f"{what}: region {k} has coefficients {coeffs.shape}, centre {centre.shape}"
                )
            if not (np.isfinite(coeffs).all() and np.isfinite(centre).all()):
                raise NeuralaoError(f"{what}: region {k} has non-finite coefficients")
            models.append(
                RegionModel(
                    centre,
                    coeffs,
                    r.get("centre_choice", ""),
                    int(r.get("valid_samples", 0)),
                    float(r.get("fit_rmse", 0.0)),
                    r.get("fallback"),
                )
            )
        edges = [
            Edge(int(e["regions"][0]), int(e["regions"][1]), float(e["area"]), tuple(map(float, e["centre"])))
            for e in data.get("edges", [])
        ]
        halves = tuple(float(v) for v in data["half_distances"])
        blend = float(data["blend"])
        if len(halves) != 2 or not all(math.isfinite(h) and h > 0 for h in halves):
            raise NeuralaoError(f"{what}: half_distances must be two positive numbers, got {list(halves)}")
        if not 0.0 <= blend <= 1.0:
            raise NeuralaoError(f"{what}: blend must be in [0, 1], got {blend}")
    except NeuralaoError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise NeuralaoError(f"{what}: malformed volumes file ({type(e).__name__}: {e})") from None
    check_regions(regions, what)
    return Volumes(
        regions, edges, models, halves, blend, settings, data.get("scene", {}), data.get("stats", {})
    )


def read_volumes(path: str | Path) -> Volumes:
    """The models of a VOLUMES.json (bounded UTF-8 JSON, known keys only, finite numbers); one-line errors."""
    return from_json(read_json(Path(path), "volumes file"), str(path))


def _known_keys(item: dict, known: tuple[str, ...], what: str, kind: str) -> None:
    unknown = sorted(set(item) - set(known))
    if unknown:
        raise NeuralaoError(f"{what}: unknown {kind} {unknown[0]!r} (known: {', '.join(known)})")
