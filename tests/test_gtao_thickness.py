"""GTAO's optional thickness heuristics (``GTAOSettings.thickness_blend``, ``thin_occluder_compensation``).

Off, the shader and the manifest entry are plain GTAO's exactly: the shipped hybrid's committed
``gtao.frag`` and manifest entry, and the pinned hash of a non-default shader made before the heuristics
existed. On, a closed form where they must help: a thin strip floating one unit in front of a plane seen
head-on. Plain GTAO takes the strip for the top of a solid wall reaching back to the plane and darkens
the plane below it; walking past the strip, the samples fall back onto the plane (the tangent plane's
horizon), so the blend pulls the horizon down and the pixel opens up, while a pixel whose radius never
reaches the strip sees the plane alone and keeps plain GTAO's value.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

from neuralao.runtime.baselines import (
    GTAOSettings,
    fragment_source,
    gtao_pass_description,
    gtao_settings_entry,
    run_gtao,
)
from neuralao.runtime.foundation.errors import NeuralaoError

ROOT = Path(__file__).resolve().parents[1]
HYBRID = ROOT / "runtime" / "models" / "unet-gtao"
# sha256 of fragment_source("gtao", GTAOSettings(slices=2, steps=4, falloff=0.5, noise_size=3, blur=False,
# seed=5)) as the template filled it before the thickness fields existed
PLAIN_NON_DEFAULT_SHA256 = "d7ee65712cb6e8fe7976ffb0d8ea975a015a22c41b1bbf122c9d1ae16a9fb35b"


def _entries(node, found):
    """Every GTAO pass description (a dict with noise, uniforms and settings) inside a manifest."""
    if isinstance(node, dict):
        if {"noise", "uniforms", "settings"} <= node.keys():
            found.append(node)
        for v in node.values():
            _entries(v, found)
    elif isinstance(node, list):
        for v in node:
            _entries(v, found)
    return found


def test_off_is_plain_gtao_exactly():
    shipped = (HYBRID / "glsl" / "internal" / "gtao.frag").read_text()
    assert fragment_source("gtao", GTAOSettings()) == shipped
    other = GTAOSettings(slices=2, steps=4, falloff=0.5, noise_size=3, blur=False, seed=5)
    assert hashlib.sha256(fragment_source("gtao", other).encode()).hexdigest() == PLAIN_NON_DEFAULT_SHA256
    entries = _entries(json.loads((HYBRID / "manifest.json").read_text()), [])
    assert entries
    for entry in entries:
        assert {k: v for k, v in entry.items() if k != "resolution"} == gtao_pass_description()
    assert set(gtao_settings_entry(GTAOSettings())) == {
        "slices",
        "steps",
        "falloff",
        "noise_size",
        "blur",
        "seed",
    }


def test_on_changes_the_shader_and_the_entry():
    on = GTAOSettings(thickness_blend=0.9)
    text = fragment_source("gtao", on)
    assert text != fragment_source("gtao", GTAOSettings())
    assert text.count("hc0 = mix(hc0, min(hc0, mix(low0, dot(d / dist, view_v), w)), 0.9);") == 1
    assert gtao_pass_description(on)["settings"]["thickness_blend"] == 0.9
    assert "thin_occluder_compensation" not in gtao_pass_description(on)["settings"]
    comp = GTAOSettings(thin_occluder_compensation=0.5)
    assert "d.z * 1.5" in fragment_source("gtao", comp)
    assert gtao_pass_description(comp)["settings"]["thin_occluder_compensation"] == 0.5


@pytest.mark.parametrize(
    "bad",
    [
        {"thickness_blend": 1.0},
        {"thickness_blend": -0.1},
        {"thickness_blend": math.nan},
        {"thin_occluder_compensation": -1.0},
        {"thin_occluder_compensation": math.inf},
    ],
)
def test_out_of_range_is_refused(bad):
    with pytest.raises(NeuralaoError, match=next(iter(bad))):
        gtao_pass_description(GTAOSettings(**bad))


H = W = 64
YFOV = math.radians(60.0)
PLANE, STRIP = 4.0, 3.0  # view depths: the plane, and the strip one unit in front of it
STRIP_ROWS = slice(16, 20)  # 4 rows, about 0.2 units tall at depth 3
RADIUS = 1.5  # about 21 px at the plane's depth
NEAR_ROWS = slice(24, 28)  # 4-8 px below the strip: samples up the slice cross it, then the plane
FAR_ROWS = slice(48, 60)  # over 28 px below it: no sample reaches the strip


def _strip_frame() -> dict:
    depth = np.full((H, W), PLANE, np.float32)
    depth[STRIP_ROWS] = STRIP
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 2] = 1.0  # both face the camera
    return {"depth": depth, "normal_cam": normal, "mask": np.ones((H, W), bool), "yfov": YFOV}


def test_a_thin_strip_in_front_of_a_plane_darkens_less():
    frame = _strip_frame()
    cols = slice(8, W - 8)
    plain = run_gtao(frame, RADIUS, GTAOSettings(blur=False))
    # plain GTAO darkens the plane under the strip hard; far from it the plane alone is open (1 exactly,
    # up to the samples' snapping to pixels)
    assert plain[NEAR_ROWS, cols].mean() < 0.75
    assert plain[FAR_ROWS, cols].min() > 0.97
    previous = plain[NEAR_ROWS, cols].mean()
    for beta in (0.5, 0.95):
        ao = run_gtao(frame, RADIUS, GTAOSettings(blur=False, thickness_blend=beta))
        near = ao[NEAR_ROWS, cols].mean()
        assert near > previous + 0.02, (beta, near, previous)  # opens up, more with a larger blend
        assert (ao >= plain - 1e-6).all()  # a horizon only ever pulled down: never darker
        assert np.abs(ao[FAR_ROWS] - plain[FAR_ROWS]).max() < 0.02  # the plane alone: barely moved
        previous = near
    assert previous > 0.95
    # XeGTAO's compensation: the strip one unit in front falls out of the stretched falloff radius
    ao = run_gtao(frame, RADIUS, GTAOSettings(blur=False, thin_occluder_compensation=0.7))
    assert ao[NEAR_ROWS, cols].mean() > 0.95
    assert (ao >= plain - 1e-6).all()
    assert np.abs(ao[FAR_ROWS] - plain[FAR_ROWS]).max() < 1e-6  # the plane's own samples: z offset 0
