"""Save a PNG of a live dashboard page, e.g. for the README during a training run.

Opens the page in headless Chromium (Debian's ``chromium``, driven by Playwright), waits until the
page has drawn the teacher's state, and saves a full-page screenshot:

    .venv/bin/python bench/dashboard_screenshot.py http://127.0.0.1:8000/curricula/kuka-alp-gmm \
        --output docs/dashboard.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from playwright.sync_api import Browser, Playwright, sync_playwright

DEBIAN_CHROMIUM = Path("/usr/bin/chromium")

CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
]
"""Headless on a closed machine: no sandbox (containers), and none of Chromium's own background
traffic, which would only produce refused connections."""


def launch_chromium(playwright: Playwright, executable: Path = DEBIAN_CHROMIUM) -> Browser:
    """Headless Debian Chromium; Playwright's own browser downloads are never used."""
    return playwright.chromium.launch(executable_path=str(executable), args=CHROMIUM_ARGS)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url", help="a dashboard page, e.g. http://127.0.0.1:8000/curricula/NAME")
    parser.add_argument("--output", type=Path, default=Path("docs/dashboard.png"), help="PNG to write")
    parser.add_argument("--width", type=int, default=1400, help="viewport width in CSS pixels")
    parser.add_argument("--height", type=int, default=900, help="viewport height; the whole page is saved")
    parser.add_argument("--scale", type=float, default=1.0, help="device pixel ratio (2 for a sharper image)")
    parser.add_argument("--settle-s", type=float, default=3.0, help="extra wait after the first draw, for more polls")
    parser.add_argument("--chromium", type=Path, default=DEBIAN_CHROMIUM, help="Chromium executable")
    args = parser.parse_args(argv)

    args.output.parent.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as playwright:
        browser = launch_chromium(playwright, args.chromium)
        page = browser.new_page(viewport={"width": args.width, "height": args.height}, device_scale_factor=args.scale)
        page.goto(args.url)
        page.wait_for_function("document.getElementById('updated').textContent !== ''", timeout=30_000)
        page.wait_for_timeout(args.settle_s * 1000)
        if page.locator("#banner").is_visible():
            print(f"warning: the page shows: {page.locator('#banner').inner_text()}", file=sys.stderr)
        page.screenshot(path=args.output, full_page=True)
        browser.close()
    print(f"saved {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
