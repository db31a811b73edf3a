"""``mcl explore motion``: draw samples of a motion model from one pose, as a PNG or a Rerun recording.

Shows the seeds' banana-shaped clouds (Prob. Rob. Figs. 5.3 and 5.8) and how
the alphas shape them: each ``--alphas`` setting is one panel, side by side,
on a common scale. ``--steps K`` applies the model K times in a row (the
seeds' "repeated application for small displacements").
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import textwrap
from pathlib import Path

import numpy as np

from mcl.errors import MclError

PANEL = 480  # px, square panel
MARGIN = 24


def sample_clouds(pose, *, model: str, odom=None, velocity=None, alphas_list=((None),), samples: int = 1000,
                  steps: int = 1, motion_cfg=None, seed: int = 0):
    """[(label, clouds)] per alpha setting: clouds is a list of (3, samples) arrays, one per step.

    odom: (x0, y0, th0, x1, y1, th1), the odometry pair (model odometry);
    velocity: (v, w, dt) (model velocity). alphas_list: tuples of 4 or 6
    alphas (None: the config's). The same seed for every panel.
    """
    from mcl.config import MotionConfig
    from mcl.motion import make_motion_model

    base = motion_cfg or MotionConfig()
    pose = np.asarray(pose, dtype=np.float64)
    out = []
    for alphas in alphas_list:
        changes = {"model": model}
        if alphas is not None:
            changes.update({f"alpha{k + 1}": float(a) for k, a in enumerate(alphas)})
        cfg = dataclasses.replace(base, **changes)
        m = make_motion_model(cfg)
        rng = np.random.default_rng(seed)
        p = np.tile(pose[:, None], (1, samples))
        clouds = []
        for _ in range(steps):
            if model != "velocity":  # odometry, omni: the odometry pair
                p, _, _ = m.sample(p, np.asarray(odom[:3]), np.asarray(odom[3:]), rng)
            else:
                p, _, _ = m.sample(p, velocity[0], velocity[1], velocity[2], rng)
            clouds.append(p)
        a = [getattr(cfg, f"alpha{k}") for k in range(1, 5 if model != "velocity" else 7)]
        out.append(("alphas: " + ", ".join(f"{x:g}" for x in a), clouds))
    return out


def render_png(path, pose, panels, title: str = "") -> None:
    """Panels side by side: start pose (red arrow), samples of each step (dark to light), labels."""
    from PIL import Image, ImageDraw

    allp = np.concatenate([c for _, clouds in panels for c in clouds], axis=1)
    xs = np.append(allp[0], pose[0])
    ys = np.append(allp[1], pose[1])
    lo = np.array([np.percentile(xs, 0.2), np.percentile(ys, 0.2)])
    hi = np.array([np.percentile(xs, 99.8), np.percentile(ys, 99.8)])
    lo = np.minimum(lo, pose[:2])
    hi = np.maximum(hi, pose[:2])
    span = float(max(hi - lo)) * 1.15 + 1e-9
    mid = (lo + hi) / 2
    scale = (PANEL - 2 * MARGIN) / span
    w = len(panels) * PANEL
    # the title in lines that fit the panels' width (it ran off the right edge of one panel)
    lines = textwrap.wrap(title, width=max(20, (w - 16) // 6)) if title else []
    img = Image.new("RGB", (w, PANEL + 16 + 14 * max(len(lines), 1)), "white")
    d = ImageDraw.Draw(img)
    for i, line in enumerate(lines):
        d.text((8, PANEL + 8 + 14 * i), line, fill=(0, 0, 0))

    def to_px(x, y, k):
        return (k * PANEL + PANEL / 2 + (x - mid[0]) * scale, PANEL / 2 - (y - mid[1]) * scale)

    for k, (label, clouds) in enumerate(panels):
        d.rectangle([k * PANEL, 0, (k + 1) * PANEL - 1, PANEL - 1], outline=(200, 200, 200))
        # 1 m scale bar (or 0.1 m when the view is small)
        bar = 1.0 if span > 2.0 else 0.1
        x0 = k * PANEL + MARGIN
        d.line([x0, PANEL - 12, x0 + bar * scale, PANEL - 12], fill=(0, 0, 0), width=2)
        d.text((x0, PANEL - 26), f"{bar:g} m", fill=(0, 0, 0))
        d.text((k * PANEL + 8, 6), label, fill=(0, 0, 0))
        for j, c in enumerate(clouds):
            shade = int(40 + 160 * (j / max(len(clouds) - 1, 1)))
            col = (shade // 3, shade // 3, 120 + shade // 2)
            for x, y in zip(*to_px(c[0], c[1], k)):
                d.point((float(x), float(y)), fill=col)
        px, py = to_px(pose[0], pose[1], k)
        ex, ey = to_px(pose[0] + 0.08 * span * math.cos(pose[2]), pose[1] + 0.08 * span * math.sin(pose[2]), k)
        d.line([px, py, ex, ey], fill=(220, 0, 0), width=3)
        d.ellipse([px - 4, py - 4, px + 4, py + 4], outline=(220, 0, 0), width=2)
    import io

    from mcl.trajectory import atomic_write_bytes

    buf = io.BytesIO()
    img.save(buf, format="PNG")
    atomic_write_bytes(path, buf.getvalue())  # a failed write keeps an earlier file whole


def _parse_alphas(texts, model: str):
    if not texts:
        return [None]
    need = 6 if model == "velocity" else 4
    out = []
    for t in texts:
        try:
            vals = [float(v) for v in t.replace(",", " ").split()]
        except ValueError:
            raise MclError(f"--alphas {t!r}: expected {need} numbers separated by commas") from None
        if len(vals) != need or any(v < 0 or not math.isfinite(v) for v in vals):
            raise MclError(f"--alphas {t!r}: expected {need} numbers >= 0 for the {model} model")
        out.append(tuple(vals))
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``mcl explore motion``."""
    p.add_argument("--pose", nargs=3, type=float, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "TH"),
                   help="start pose (m, m, rad); default 0 0 0")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--odom", nargs=6, type=float, metavar=("X0", "Y0", "TH0", "X1", "Y1", "TH1"),
                   help="odometry pair (models odometry and omni); default a 1 m step turning 0.5 rad")
    g.add_argument("--velocity", nargs=3, type=float, metavar=("V", "W", "DT"),
                   help="velocity command and duration (model velocity); default 1 m/s, 0.5 rad/s, 1 s")
    p.add_argument("--model", choices=["odometry", "omni", "velocity"],
                   help="default: velocity with --velocity, else odometry; omni: an omnidirectional base's odometry "
                   "(its strafe noise from motion.alpha_strafe)")
    p.add_argument("--alphas", action="append", default=[], metavar="A1,A2,...",
                   help="alpha1..alpha4 (odometry, omni) or alpha1..alpha6 (velocity); repeat for panels side by side")
    p.add_argument("--samples", type=int, default=1000, help="samples per step (default 1000)")
    p.add_argument("--steps", type=int, default=1, help="apply the model this many times in a row (default 1)")
    p.add_argument("--config", help="config whose motion section gives the defaults (noise form, noise, alphas)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="config override, e.g. motion.noise=triangular")
    p.add_argument("--seed", type=int, default=0, help="random seed of the samples drawn (default 0)")
    p.add_argument("--out", default="motion.png", help="FILE.png (Pillow) or FILE.rrd (Rerun); default motion.png")


def run_from_args(args) -> int:
    from mcl.config import load_config

    model = args.model or ("velocity" if args.velocity else "odometry")
    if model != "velocity" and args.velocity:
        raise MclError("--velocity needs --model velocity")
    if model == "velocity" and args.odom:
        raise MclError("--odom needs --model odometry or omni")
    if not 1 <= args.samples <= 10_000_000 or not 1 <= args.steps <= 1000:
        raise MclError("--samples must be 1..1e7 and --steps 1..1000")
    cfg = load_config(args.config, list(args.set))
    out = Path(str(args.out))
    if not out.name.lower().endswith((".png", ".rrd")):
        raise MclError(f"--out {out}: expected a .png or .rrd file")
    if not out.parent.is_dir():  # said before the sampling, not after it
        raise MclError(f"--out {out}: the folder {out.parent} does not exist")
    odom = tuple(args.odom) if args.odom else (0.0, 0.0, 0.0, math.cos(0.25), math.sin(0.25), 0.5)
    for option, values in (("--pose", args.pose), ("--odom", odom)):
        if not all(math.isfinite(v) for v in values):
            raise MclError(f"{option}: expected finite numbers, got {' '.join(f'{v:g}' for v in values)}")
    vel = tuple(args.velocity) if args.velocity else (1.0, 0.5, 1.0)
    if not (all(math.isfinite(v) for v in vel) and vel[2] > 0):
        raise MclError(f"--velocity: expected finite V W and DT > 0 (s), got {' '.join(f'{v:g}' for v in vel)}")
    panels = sample_clouds(args.pose, model=model, odom=odom, velocity=vel, alphas_list=_parse_alphas(args.alphas, model),
                           samples=args.samples, steps=args.steps, motion_cfg=cfg.motion, seed=args.seed)
    pose = np.asarray(args.pose, dtype=np.float64)
    control = (f"odom ({', '.join(f'{v:.4g}' for v in odom[:3])}) -> ({', '.join(f'{v:.4g}' for v in odom[3:])})"
               if model != "velocity" else f"v={vel[0]:g} w={vel[1]:g} dt={vel[2]:g}")
    title = f"{model} model, {control}, noise {cfg.motion.noise} ({cfg.motion.noise_form}), {args.samples} samples x {args.steps}"
    try:
        if out.name.lower().endswith(".rrd"):
            from mcl.viz import log_motion_samples

            log_motion_samples(out, pose, panels)
        else:
            render_png(out, pose, panels, title)
    except OSError as e:
        raise MclError(f"--out {out}: cannot write: {e.strerror or e}") from None
    print(f"wrote {out}: {len(panels)} panel(s), {title}")
    return 0
