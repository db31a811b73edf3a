"""Screenshots of a recording in the real Rerun viewer, headless: how a user sees it, at chosen steps.

    apt-get install -y mesa-vulkan-drivers        # Debian's software Vulkan renderer (llvmpipe), once
    python scripts/viewer_shots.py runs/x/recording.rrd --steps 0,2,252,349 --out shots/

Writes ``full_stepNNNN.png`` (the whole window, 1920 x 1080), ``world_stepNNNN.png`` (the World view alone) and
``robot_stepNNNN.png`` (the view that follows the estimate; the blueprint has it on maps over 60 m across only) per
step, and one PNG per time-series panel at the last step. The recording is loaded, then paused at each step (the
blueprint plays on load, and a headless viewer plays about 6x faster than real time). Rerun 0.41's
``rerun.experimental.ViewerClient``; about 1 s a screenshot with the software renderer.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("rrd", type=Path, help="a recording (.rrd) written by mcl run")
    ap.add_argument("--steps", default="0", help="comma-separated steps (the 'step' timeline)")
    ap.add_argument("--out", type=Path, default=Path("shots"), help="folder for the PNG files")
    ap.add_argument("--port", type=int, default=9877, help="the headless viewer's control port")
    ap.add_argument("--settle", type=float, default=4.0, help="s to wait after loading (chunks keep arriving)")
    a = ap.parse_args(argv)
    from rerun.experimental import ViewerClient

    a.out.mkdir(parents=True, exist_ok=True)
    rerun_exe = Path(sys.executable).with_name("rerun")
    client = ViewerClient.spawn(headless=True, port=a.port, hide_welcome_screen=True,
                                **({"executable_path": str(rerun_exe)} if rerun_exe.exists() else {}))
    try:
        for _ in range(60):  # the viewer answers once it is up
            try:
                client.get_state()
                break
            except Exception:
                time.sleep(0.5)
        client.open(str(a.rrd.resolve()))
        while client.get_state().loading:
            time.sleep(0.1)
        time.sleep(a.settle)
        views = client.get_state().views
        # the whole-map view ("World") as world_*, the one that follows the estimate ("Robot: ...") as robot_*
        spatial = [(("world" if v.name == "World" else v.name.split(":")[0].lower()), v.view_id)
                   for v in views if v.view_class == "2D"]
        for s in (int(v) for v in a.steps.split(",")):
            client.set_time("step", sequence=s, play_state="paused")
            time.sleep(0.3)
            (a.out / f"full_step{s:04d}.png").write_bytes(client.take_screenshot())
            for prefix, view_id in spatial:
                (a.out / f"{prefix}_step{s:04d}.png").write_bytes(client.take_screenshot(view_id=view_id))
        for v in client.get_state().views:  # a view in an inactive tab is not drawn: skipped
            if v.view_class in ("TimeSeries", "BarChart"):
                name = "".join(ch if ch.isalnum() else "_" for ch in v.name)[:40]
                try:
                    png = client.take_screenshot(view_id=v.view_id)
                except Exception:
                    continue
                if png:
                    (a.out / f"view_{name}.png").write_bytes(png)
        for v in client.get_state().views:
            if v.reports:
                print(f"{v.name}: {v.reports}", file=sys.stderr)
    finally:
        client.quit()
    print(f"{a.out}: {len(list(a.out.glob('*.png')))} screenshots")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
