"""Headless Chromium (Debian's ``chromium`` + ``chromium-driver``, driven by selenium) for the viewer page.

The tests of the page and of the WGSL browser runner, and ``bench/viewer_screenshot.py`` (run by
``make demo`` as a plain script), all start the same browser and wait for the same page. The code lives
here, next to the page it drives (runtime/viewer.py), because that is where both can import it: the
installed package holds ``runtime``, while ``tests/`` is no package and a script under ``bench/`` could
only reach it by editing ``sys.path``. selenium is a dev dependency, so it is imported inside
:func:`headless_chromium` only: importing this module needs nothing a consumer lacks.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

# WebGL2 on SwiftShader (Chromium's CPU GL), without the GPU process's WebGPU.
SWIFTSHADER_WEBGL = ("--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader")
# The page's [ready, error] once its script has run; null before.
_PAGE_STATE = "return window.neuralao ? [window.neuralao.ready, window.neuralao.error] : null"


def chromium_paths() -> tuple[str | None, str | None]:
    """The ``chromium`` and ``chromedriver`` executables on PATH (None where one is missing)."""
    return shutil.which("chromium"), shutil.which("chromedriver")


@contextmanager
def headless_chromium(*flags: str) -> Iterator[Any]:
    """A selenium WebDriver of headless Chromium started with ``flags`` (after ``--headless=new
    --no-sandbox``), quit when the block ends. Raises RuntimeError if chromium or its driver is missing."""
    from selenium import webdriver  # a dev dependency: imported only when a browser starts
    from selenium.webdriver.chrome.service import Service

    chromium, driver_bin = chromium_paths()
    if not (chromium and driver_bin):
        raise RuntimeError("needs Debian's chromium and chromium-driver (make system-deps)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for a in ("--headless=new", "--no-sandbox", *flags):
        opts.add_argument(a)
    driver = webdriver.Chrome(service=Service(driver_bin), options=opts)
    try:
        yield driver
    finally:
        driver.quit()


def wait_for_page(driver: Any, timeout_s: float = 60.0) -> list | None:
    """Poll the loaded viewer page until it is ready or has an error, at most ``timeout_s`` seconds.

    Returns the page's last ``[ready, error]`` (None if its script never ran); the caller judges it.
    """
    deadline = time.monotonic() + timeout_s
    state = None
    while time.monotonic() < deadline:
        state = driver.execute_script(_PAGE_STATE)
        if state and (state[0] or state[1]):
            break
        time.sleep(0.05)
    return state
