"""A Kinect-like depth camera in the simulator's world, made 2.5D (``mcl simulate --depth``).

The occupancy grid's walls stand ``wall_height`` tall on a floor at z = 0; furniture (tables, shelves,
pillars: occupied cells that are not walls) are boxes of a random height per piece (0.4-1.2 m; pillars
tall). No ceiling: rays that leave over the walls give no reading. The camera (mcl.planes.DepthCamera,
mounted on the robot) sees the first surface along each pixel's ray (mcl.kernels.planes.render_depth);
readings get the axial noise ``sigma_a + sigma_b (z - z0)^2``, then dropouts (probability ``p_dropout``),
then are stored as whole millimetres (``<t>.npz`` uint16 in ``depth/``, with ``depth/camera.yaml``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from mcl.planes import CAMERA_FILE, DepthCamera, rotation_rpy, write_depth_frame

__all__ = ["world_heights", "render", "camera_pose_world", "write_depth_folder"]

WALL_HEIGHT = 2.5


def world_heights(world, rng: np.random.Generator, wall_height: float = WALL_HEIGHT) -> np.ndarray:
    """(H, W) float64 column heights of the world's cells (0: floor)."""
    from scipy.ndimage import label

    occ = world.occupancy == 100
    h = np.where(occ, wall_height, 0.0)
    furniture = getattr(world, "furniture", None)
    if furniture is not None and furniture.any():
        lab, n = label(furniture)
        tall = rng.uniform(0.4, 1.2, n + 1)
        sizes = np.bincount(lab.ravel(), minlength=n + 1) * world.resolution ** 2
        tall = np.where(sizes < 0.2, wall_height, tall)  # pillars reach the ceiling
        h = np.where(furniture, tall[lab], h)
    return np.ascontiguousarray(h)


def camera_pose_world(pose, cam: DepthCamera) -> tuple[np.ndarray, np.ndarray]:
    """(world-from-optical rotation, camera centre) for a robot pose (x, y, theta)."""
    x, y, th = (float(v) for v in pose)
    mx, my, mz = cam.mount[:3]
    c, s = math.cos(th), math.sin(th)
    rot = rotation_rpy(0.0, 0.0, th) @ cam.level_from_optical
    return rot, np.array([x + c * mx - s * my, y + s * mx + c * my, mz])


def render(heights, origin, resolution, pose, cam: DepthCamera, rng: np.random.Generator | None) -> np.ndarray:
    """One depth image (m, 0: no reading) from robot pose ``pose``; exact when ``rng`` is None."""
    from mcl.kernels.planes import render_depth

    rot, c = camera_pose_world(pose, cam)
    out = np.zeros((cam.height, cam.width))
    render_depth(np.ascontiguousarray(rot), c, cam.fx, cam.fy, 0.5 * cam.width, 0.5 * cam.height, heights,
                 float(origin[0]), float(origin[1]), float(resolution), cam.z_max, out)
    if rng is None:
        return out
    hit = out > 0
    z = out[hit]
    noisy = z + (cam.sigma_a + cam.sigma_b * (z - cam.z0) ** 2) * rng.standard_normal(z.size)
    drop = rng.random(z.size) < cam.p_dropout
    noisy[drop | (noisy < cam.z_min) | (noisy > cam.z_max)] = 0.0
    out[hit] = noisy
    return out


def write_depth_folder(out: Path, world, poses: np.ndarray, times: np.ndarray, rng: np.random.Generator,
                       cam: DepthCamera = DepthCamera()) -> int:
    """Render a frame from each pose (M, 3) into ``out/depth/<t>.npz`` and write ``camera.yaml``.

    Returns the number of frames."""
    import yaml

    from mcl.trajectory import atomic_write_text

    folder = Path(out) / "depth"
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("*.npz"):  # an earlier world's frames in the same folder
        old.unlink()
    heights = world_heights(world, rng)
    for k in range(poses.shape[0]):
        depth = render(heights, world.origin, world.resolution, poses[k], cam, rng)
        write_depth_frame(folder, float(times[k]), depth, cam.quantization)
    head = ("# mcl depth camera: pinhole, fov in rad, ranges in m, mount = x y z roll pitch yaw on the robot;\n"
            "# noise sigma_z = sigma_a + sigma_b (z - z0)^2, frames <t>.npz: uint16 depth in units of quantization\n")
    atomic_write_text(folder / CAMERA_FILE, head + yaml.safe_dump(cam.to_dict(), sort_keys=False))
    return int(poses.shape[0])
