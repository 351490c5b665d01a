"""Screenshots of rerun recordings, taken headless (the README's pictures).

    .venv/bin/python docs/screenshots.py results/slam.rrd docs/rerun_slam.png --scan 239

Starts the native viewer of the installed rerun-sdk in its headless mode
(`rerun.experimental.ViewerClient.spawn(headless=True)`: an offscreen window, rendered by
whatever wgpu adapter the machine has; on a machine without a GPU, Mesa's llvmpipe through
Vulkan (Debian: mesa-vulkan-drivers)), opens the file with the blueprint it carries, puts the
time cursor on a scan, pauses, and saves the screenshot, scaled to --width pixels and saved as
an optimised RGB PNG (full colour; no palette). A script, not part of the package: it is only
for the documentation.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import rerun as rr
from rerun.experimental import ViewerClient


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rrd")
    ap.add_argument("png")
    ap.add_argument("--scan", type=int, default=None, help="scan index (default: the last)")
    ap.add_argument("--wait", type=float, default=8.0, help="seconds to let the viewer draw")
    ap.add_argument("--port", type=int, default=9877)
    ap.add_argument("--width", type=int, default=1280, help="pixels; 0 keeps the full size")
    a = ap.parse_args()
    viewer = ViewerClient.spawn(
        headless=True,
        port=a.port,
        hide_welcome_screen=True,
        executable_path=str(Path(sys.executable).with_name("rerun")),
    )
    try:
        viewer.open(a.rrd)
        time.sleep(a.wait / 2)
        if a.scan is None:
            viewer.set_time("scan", play_state="following")
        else:
            viewer.set_time("scan", sequence=a.scan, play_state="paused")
        time.sleep(a.wait / 2)
        viewer.save_screenshot(a.png)
    finally:
        viewer.quit()
    if a.width:  # small enough for a README: scaled down, in full colour
        from PIL import Image

        im = Image.open(a.png).convert("RGB")
        im = im.resize((a.width, round(im.height * a.width / im.width)), Image.LANCZOS)
        # RGB, not a 256-colour palette: quantising turns the thin green and brown strokes
        # (landmarks, circles, segments) grey, as they share few pixels with the dark UI
        im.save(a.png, optimize=True)
    print(f"{a.rrd} -> {a.png} (rerun {rr.__version__})")


if __name__ == "__main__":
    main()
