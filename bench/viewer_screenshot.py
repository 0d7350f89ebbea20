"""A picture of a `neuralao view` page: every method side by side, in headless Chromium.

    .venv/bin/python bench/viewer_screenshot.py PAGE_DIR --out docs/viewer.png [--pose 35 15 1.1]

PAGE_DIR is a folder written by ``neuralao view`` (or a report's ``viewer/<scene>/``). Each method is
drawn at 320x240 from the same pose (azimuth and elevation in degrees, distance in units of the
default) and labelled with its name; the panels are pasted in a row. Needs Debian's ``chromium`` and
``chromium-driver`` (``make system-deps``) and selenium (the dev dependencies). `make demo` runs it on
the demo report's bunny page to write ``build/demo/viewer.png``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

PANEL = (320, 240)


def screenshot(page: Path, out: Path, pose: tuple[float, float, float]) -> Path:
    """Write the row of panels of ``page/index.html`` to ``out`` (PNG); returns ``out``."""
    import io

    from PIL import Image, ImageDraw
    from selenium.webdriver.common.by import By

    from neuralao.runtime.chromium import SWIFTSHADER_WEBGL, chromium_paths, headless_chromium, wait_for_page

    if not all(chromium_paths()):
        raise SystemExit("viewer_screenshot: needs chromium and chromium-driver (make system-deps)")
    with headless_chromium(*SWIFTSHADER_WEBGL, "--window-size=700,600") as driver:
        driver.get((page / "index.html").resolve().as_uri() + f"?w={PANEL[0]}&h={PANEL[1]}")
        state = wait_for_page(driver, timeout_s=120)
        if not (state and state[0]) or state[1]:
            raise SystemExit(f"viewer_screenshot: the page did not load: {state}")
        shots = []
        for i, method in enumerate(driver.execute_script("return window.neuralao.methods")):
            driver.execute_script(
                f"window.neuralao.setMethod({i}); window.neuralao.setPose({pose[0]}, {pose[1]}, {pose[2]});"
            )
            shot = Image.open(io.BytesIO(driver.find_element(By.ID, "view").screenshot_as_png)).convert("RGB")
            ImageDraw.Draw(shot).text((6, 4), method["name"], fill=(230, 230, 230))
            shots.append(shot)
    sheet = Image.new("RGB", (PANEL[0] * len(shots), PANEL[1]), (255, 255, 255))
    for k, shot in enumerate(shots):
        sheet.paste(shot.resize(PANEL), (k * PANEL[0], 0))
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    sheet.save(tmp, format="PNG")
    tmp.replace(out)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("page", type=Path, help="folder of a neuralao view page (index.html)")
    p.add_argument("--out", type=Path, required=True, help="PNG to write")
    p.add_argument("--pose", type=float, nargs=3, default=(35.0, 15.0, 1.1), metavar=("AZ", "EL", "DIST"))
    args = p.parse_args(argv)
    if not (args.page / "index.html").is_file():
        sys.stderr.write(f"viewer_screenshot: error: no index.html in {args.page}\n")
        return 2
    out = screenshot(args.page, args.out, tuple(args.pose))
    print(f"viewer_screenshot: wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
