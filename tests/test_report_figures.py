"""neuralao.pipeline.evaluation.figures: crops to the object and finds the worst error window (planted
cases)."""

from __future__ import annotations

import numpy as np
from PIL import Image

from neuralao.pipeline.evaluation.figures import CROP_MARGIN, contact_sheet, crop_box, worst_window


def test_crop_box_is_the_foreground_bounding_box_plus_the_margin():
    fg = np.zeros((64, 80), bool)
    fg[20:30, 10:50] = True
    rs, cs = crop_box(fg)
    assert (rs.start, rs.stop, cs.start, cs.stop) == (
        20 - CROP_MARGIN,
        30 + CROP_MARGIN,
        10 - CROP_MARGIN,
        50 + CROP_MARGIN,
    )
    fg[:, :] = False
    fg[0, 79] = True  # clipped at the image border
    rs, cs = crop_box(fg)
    assert (rs.start, rs.stop, cs.start, cs.stop) == (0, 1 + CROP_MARGIN, 79 - CROP_MARGIN, 80)
    assert crop_box(np.zeros((5, 6), bool)) == (slice(0, 5), slice(0, 6))


def test_worst_window_finds_a_planted_error_block_and_ignores_invalid_pixels():
    err = np.random.default_rng(0).random((50, 60)) * 0.05
    err[31:39, 12:20] = 0.9
    valid = np.ones_like(err, bool)
    assert worst_window(err, valid, 8) == (31, 12)
    valid[31:39, 12:20] = False  # the block is invalid ground truth: not the worst any more
    r, c = worst_window(err, valid, 8)
    assert not (r == 31 and c == 12)


def test_contact_sheet_has_one_column_per_method(tmp_path):
    yy, xx = np.mgrid[:64, :64]
    fg = (yy - 32) ** 2 + (xx - 32) ** 2 < 15**2
    gt = np.where(fg, 0.6, 1.0)
    sheet = {"gt": gt, "mask": fg, "fg": fg, "view": 0, "images": {"a": gt, "b": gt * 0.5, "c": gt}}
    h = []
    for names in (["a"], ["a", "b", "c"]):
        with Image.open(contact_sheet("s", sheet, names, tmp_path / f"{len(names)}.png")) as im:
            assert im.format == "PNG"
            h.append(im.size[0])
    assert h[1] > 1.8 * h[0]  # columns grow with the methods


def test_shipped_picks_default_and_fast_by_role_or_by_gl_time():
    from neuralao.pipeline.evaluation.report_rows import pick_shipped
    from neuralao.pipeline.evaluation.report_writing import contact_order

    models = {
        n: {"kind": "unet", "gl_seconds": {"512x512": t}}
        for n, t in (("big", 0.8), ("mid", 0.3), ("tiny", 0.1))
    }
    summary = {"folder": "m", "models": models, "default": {"unet": "big"}, "fast": {}}
    assert pick_shipped(summary, ["default", "fast"]) == ["big", "tiny"]  # fast: least GL time
    assert pick_shipped({**summary, "fast": {"unet": "mid"}}, ["default", "fast"]) == ["big", "mid"]
    assert pick_shipped(summary, ["all"]) == ["big", "mid", "tiny"] == pick_shipped(summary, None)
    assert pick_shipped(summary, ["mid", "nonesuch"]) == ["mid"]
    result = {
        "methods": {
            n: {"family": f, "bytes": b}
            for n, f, b in (
                ("gtao", "screen-space", 256),
                ("field-32x16", "field", 6000),
                ("field-16x8", "field", 2600),
                ("shipped:tiny", "unet", 1),
                ("mlp-16x8", "mlp", 10),
            )
        },
        "shipped": {"roles": {"default": "big", "fast": "tiny"}},
    }
    assert contact_order(result, ["gtao", "field", "shipped:default", "shipped:fast"]) == [
        "gtao",
        "field-16x8",
        "shipped:tiny",
    ]
