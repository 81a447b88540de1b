#!/usr/bin/env python3
"""Render a TUM-layout sequence with depth images (7-Scenes redkitchen) again, from one
point model fused from its depth images, along its ground-truth poses: the scene and the
motion are the sequence's, the camera model is whatever --camera says and exactly known,
the texture is world-fixed 3-D value noise. A testbed for the tracker's drift (docs/slam.md,
"Redkitchen's own geometry rendered from its depth images").

  tools/render_depth_model.py ../shared/data/redkitchen /tmp/rk-render \\
      [--camera config/camera-redkitchen-fitted.txt] [--rolling-shutter 0.03] [--texture-seed 7]
  build/release/bin/slam-run --dataset /tmp/rk-render --json --seed N            # the exact camera
  build/release/bin/slam-run --dataset /tmp/rk-render --json --seed N \\
      --camera ../shared/data/redkitchen/camera.txt                              # the shared one

The model: every depth image median-filtered (5 px), replaced by the median over the 13
frames around it sampled along its own rays, every third frame's points (every second pixel)
averaged in 4 mm voxels. The depth images are taken to be in the source camera.txt's
pinhole and the ground-truth pose's frame (7-Scenes: the depth camera). Each frame: the
model's points projected through --camera (k1, k2 radial distortion; with a rolling shutter
row r seen S r / (H - 1) s after row 0, the pose moved by the ground truth's velocities),
2x2 splats in a depth buffer, farther points seen through a nearer surface's gaps removed,
small gaps filled, each pixel's 3-D point textured (value noise of 6 and 3 cm cells), holes
inpainted, pixel noise sigma 2. Writes OUT/rgb/*.png, rgb.txt, camera.txt (the render's
camera), groundtruth.txt and gravity.txt (the source's); with --depth-out also the rendered
depth (depth/, depth.txt), so that the render is an RGB-D sequence of its own. Needs
python3-numpy and python3-opencv; about 4 minutes for 600 frames on 2 cores (15 with a
rolling shutter).
"""
import argparse
import os
import sys
from multiprocessing import Pool

import cv2
import numpy as np

cv2.setNumThreads(0)
G = {}  # the workers' state (set before the pool forks)


def rows(path):
    with open(path) as f:
        return [line.split() for line in f if line.strip() and not line.startswith("#")]


def read_camera(path):
    r = rows(path)
    if not r or len(r[0]) not in (6, 8):
        sys.exit(f"{path}: expected 'width height fx fy cx cy [k1 k2]'")
    v = [float(x) for x in r[0]] + ([0.0, 0.0] if len(r[0]) == 6 else [])
    return int(v[0]), int(v[1]), v[2], v[3], v[4], v[5], v[6], v[7]


def undistorted_rays(w, h, fx, fy, cx, cy, k1=0.0, k2=0.0):
    """Each pixel's ray (x, y, 1) through a camera with radial distortion k1, k2 (h x w x 3)."""
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    xd, yd = (u - cx) / fx, (v - cy) / fy
    xu, yu = xd.copy(), yd.copy()
    for _ in range(30 if k1 or k2 else 0):  # x_d = x_u (1 + k1 r_u^2 + k2 r_u^4), by fixed point
        r2 = xu * xu + yu * yu
        d = 1 + k1 * r2 + k2 * r2 * r2
        xu, yu = xd / d, yd / d
    return np.stack([xu, yu, np.ones_like(u)], -1)


def quat_to_r(x, y, z, w):
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def pose(k):
    r = G["gt"][k]
    return quat_to_r(*[float(x) for x in r[4:8]]), np.array([float(x) for x in r[1:4]])


def log_r(r):
    a = np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return w * (0.5 if a < 1e-9 else a / (2 * np.sin(a)))


def exp_r(w):
    """Rotation matrices of the rows of w (n x 3)."""
    a = np.linalg.norm(w, axis=-1)[..., None, None]
    k = np.zeros(w.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = w[..., 2], -w[..., 1], w[..., 0]
    with np.errstate(all="ignore"):
        s = np.where(a > 1e-9, np.sin(a) / a, 1.0)
        c = np.where(a > 1e-9, (1 - np.cos(a)) / (a * a), 0.5)
    return np.eye(3) + s * k + c * (k @ k)


def rates(k):
    """The ground truth's rotation rate (camera frame, rad/s) and velocity (world, m/s)."""
    a, b = max(k - 1, 0), min(k + 1, len(G["gt"]) - 1)
    ra, ta = pose(a)
    rb, tb = pose(b)
    dt = float(G["gt"][b][0]) - float(G["gt"][a][0])
    return log_r(ra.T @ rb) / dt, (tb - ta) / dt


# --- the fused model ---------------------------------------------------------------------
_raw = {}


def raw_depth(k):
    if k not in _raw:
        if len(_raw) > 24:
            _raw.pop(max(_raw, key=lambda q: abs(q - k)))
        img = cv2.imread(os.path.join(G["src"], G["depth"][k][1]), cv2.IMREAD_UNCHANGED)
        if img is None:
            sys.exit(f"{G['src']}: cannot read depth image {G['depth'][k][1]}")
        _raw[k] = cv2.medianBlur(img, 5).astype(np.float64) / 1000
    return _raw[k]


def temporal_median_depth(k, half=6):
    """Frame k's depth, each pixel the median over frames k-half..k+half along its ray."""
    w, h, fx, fy, cx, cy = G["src_cam"]
    ray = G["src_ray"]
    z = raw_depth(k)
    rk, tk = pose(k)
    pw = (ray * z[..., None]) @ rk.T + tk
    stack = [np.where(z > 0, z, np.nan)]
    for j in range(max(0, k - half), min(len(G["depth"]), k + half + 1)):
        if j == k:
            continue
        rj, tj = pose(j)
        pj = (pw - tj) @ rj
        with np.errstate(all="ignore"):
            uj = np.rint(fx * pj[..., 0] / pj[..., 2] + cx)
            vj = np.rint(fy * pj[..., 1] / pj[..., 2] + cy)
        ok = (z > 0) & (pj[..., 2] > 0.1) & (uj >= 0) & (uj < w) & (vj >= 0) & (vj < h)
        ui = np.where(ok, uj, 0).astype(np.int64)
        vi = np.where(ok, vj, 0).astype(np.int64)
        zj = raw_depth(j)[vi, ui]
        q = ray[vi, ui] * zj[..., None] @ rj.T + tj
        zk = ((q - tk) @ rk)[..., 2]
        stack.append(np.where(ok & (zj > 0) & (np.abs(zk - z) < 0.05 * z), zk, np.nan))
    with np.errstate(all="ignore"):
        zm = np.nanmedian(np.stack(stack), axis=0)
    return np.where(np.isfinite(zm), zm, 0)


def fuse(n, every=3, voxel_m=0.004):
    ray = G["src_ray"][::2, ::2]
    pts = []
    for k in range(0, n, every):
        z = temporal_median_depth(k)[::2, ::2]
        rk, tk = pose(k)
        m = z > 0
        pts.append(((ray[m] * z[m][:, None]) @ rk.T + tk).astype(np.float32))
    p = np.concatenate(pts)
    q = np.floor(p / voxel_m).astype(np.int64) + (1 << 20)
    key = (q[:, 0] << 42) | (q[:, 1] << 21) | q[:, 2]
    _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    return np.stack([np.bincount(inv, weights=p[:, i]) / cnt for i in range(3)], 1).astype(np.float32)


# --- the texture and the frames ----------------------------------------------------------
def value_noise(p, cell):
    q = p / cell
    i = np.floor(q).astype(np.int64)
    f = (q - i).astype(np.float32)
    f = f * f * (3 - 2 * f)
    table = G["table"]
    acc = 0
    for dx in (0, 1):
        wx = f[:, 0] if dx else 1 - f[:, 0]
        for dy in (0, 1):
            wy = f[:, 1] if dy else 1 - f[:, 1]
            for dz in (0, 1):
                wz = f[:, 2] if dz else 1 - f[:, 2]
                h = ((i[:, 0] + dx) * 73856093) ^ ((i[:, 1] + dy) * 19349663) ^ ((i[:, 2] + dz) * 83492791)
                acc = acc + wx * wy * wz * table[h & ((1 << 20) - 1)]
    return acc - 0.5


def render(k):
    w, h, f, _, cx, cy, k1, k2 = G["cam"]
    rs = G["rolling_shutter_s"]
    cloud = G["cloud"]
    r, t = pose(k)
    w_c, v_w = rates(k)
    pc = (cloud - t.astype(np.float32)) @ r.astype(np.float32)
    m = (pc[:, 2] > 0.2) & (np.abs(pc[:, 0]) < 1.5 * pc[:, 2]) & (np.abs(pc[:, 1]) < 1.5 * pc[:, 2])
    pw, pc = cloud[m], pc[m]

    def project(pc):
        z = pc[:, 2]
        x, y = pc[:, 0] / z, pc[:, 1] / z
        r2 = x * x + y * y
        d = 1 + k1 * r2 + k2 * r2 * r2
        return f * x * d + cx, f * y * d + cy, z

    uf, vf, z = project(pc)
    if rs > 0:  # each point seen at its row's time: two fixed-point passes
        for _ in range(2):
            dt = rs * np.clip(vf, 0, h - 1) / (h - 1)
            r_row = r @ exp_r(w_c[None, :] * dt[:, None])
            pc = np.einsum("nji,nj->ni", r_row, pw - (t[None, :] + v_w[None, :] * dt[:, None]))
            uf, vf, z = project(pc.astype(np.float32))
    m = z > 0.2
    uu, vv, z = np.floor(uf[m]).astype(np.int64), np.floor(vf[m]).astype(np.int64), z[m]
    m = (uu >= -1) & (uu < w) & (vv >= -1) & (vv < h)
    uu, vv, z = uu[m], vv[m], z[m]
    o = np.argsort(-z)
    uu, vv, z = uu[o], vv[o], z[o]
    buf = np.full((h + 2) * (w + 2), np.inf, np.float32)
    for du in (0, 1):
        for dv in (0, 1):
            idx = (vv + dv + 1) * (w + 2) + (uu + du + 1)
            buf[idx] = np.minimum(buf[idx], z)
    depth = buf.reshape(h + 2, w + 2)[1:-1, 1:-1].copy()
    with np.errstate(all="ignore"):  # a farther surface seen through the gaps of a nearer one
        near = cv2.erode(depth, np.ones((5, 5), np.uint8))
        depth[depth > near * 1.05 + 0.01] = np.inf
        for _ in range(3):
            depth = np.where(np.isfinite(depth), depth, cv2.erode(depth, np.ones((3, 3), np.uint8)))
    # OpenCV's erosion pads with FLT_MAX: a pixel no point reaches is a hole
    hole = ~(depth < 1e6)
    depth = np.where(hole, 0, depth).astype(np.float32)
    if G["depth_out"]:
        cv2.imwrite(os.path.join(G["out"], "depth", "%06d.png" % k),
                    np.clip(np.rint(depth * 1000), 0, 65535).astype(np.uint16))
    p_cam = G["ray"].reshape(-1, 3) * depth.reshape(-1, 1)
    if rs > 0:
        dt = rs * np.repeat(np.arange(h, dtype=np.float64), w) / (h - 1)
        r_row = r @ exp_r(w_c[None, :] * dt[:, None])
        p = np.einsum("nij,nj->ni", r_row, p_cam) + t[None, :] + v_w[None, :] * dt[:, None]
    else:
        p = p_cam @ r.T + t
    val = value_noise(p, 0.06) + 0.6 * value_noise(p, 0.03)
    img = np.clip(128 + 300 * val, 0, 255).astype(np.uint8).reshape(h, w)
    if hole.any():
        img = cv2.inpaint(img, cv2.dilate(hole.astype(np.uint8), np.ones((5, 5), np.uint8)), 5,
                          cv2.INPAINT_TELEA)
    noise = np.random.default_rng(1000 + k).normal(0, 2, img.shape)
    cv2.imwrite(os.path.join(G["out"], "rgb", "%06d.png" % k), np.clip(img + noise, 0, 255).astype(np.uint8))
    return hole.mean()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src", help="TUM-layout sequence with depth.txt, groundtruth.txt, camera.txt")
    ap.add_argument("out", help="the rendered sequence's directory (created)")
    ap.add_argument("--camera", help="the render's camera (camera.txt format, k1 k2 optional; "
                    "fx = fy is used); default: the source's camera.txt")
    ap.add_argument("--rolling-shutter", type=float, default=0.0, metavar="S",
                    help="seconds from the first row's exposure to the last's (default 0)")
    ap.add_argument("--texture-seed", type=int, default=7, help="the value noise's draw (default 7)")
    ap.add_argument("--frames", type=int, default=0, help="the first N frames only (default all)")
    ap.add_argument("--procs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--model", help="the fused model's cache (.npy): read if it exists, else written")
    ap.add_argument("--depth-out", action="store_true",
                    help="also write each frame's rendered depth (depth/, depth.txt: 16-bit, mm, "
                    "0 where no point; with a rolling shutter each row's own camera)")
    a = ap.parse_args()
    src = a.src
    for name in ("depth.txt", "groundtruth.txt", "camera.txt"):
        if not os.path.exists(os.path.join(src, name)):
            sys.exit(f"{src}: no {name} (a TUM-layout sequence with depth images is needed)")
    G["src"] = src
    G["out"] = a.out
    G["depth"] = rows(os.path.join(src, "depth.txt"))
    G["gt"] = rows(os.path.join(src, "groundtruth.txt"))
    if len(G["gt"]) != len(G["depth"]):
        sys.exit(f"{src}: {len(G['depth'])} depth images but {len(G['gt'])} poses")
    sw, sh, sfx, sfy, scx, scy, sk1, sk2 = read_camera(os.path.join(src, "camera.txt"))
    if sk1 or sk2:
        sys.exit(f"{src}/camera.txt: the depth images are taken as undistorted pinhole images")
    G["src_cam"] = (sw, sh, sfx, sfy, scx, scy)
    G["src_ray"] = undistorted_rays(sw, sh, sfx, sfy, scx, scy)
    cam = read_camera(a.camera) if a.camera else (sw, sh, sfx, sfy, scx, scy, 0.0, 0.0)
    G["cam"] = cam
    w, h, f, _, cx, cy, k1, k2 = cam
    G["ray"] = undistorted_rays(w, h, f, f, cx, cy, k1, k2)
    G["rolling_shutter_s"] = a.rolling_shutter
    n = min(a.frames, len(G["depth"])) if a.frames > 0 else len(G["depth"])
    if a.model and os.path.exists(a.model):
        G["cloud"] = np.load(a.model)
    else:
        G["cloud"] = fuse(n)
        if a.model:
            np.save(a.model, G["cloud"])
    print(f"model: {len(G['cloud'])} points", file=sys.stderr)
    G["table"] = np.random.default_rng(a.texture_seed).random(1 << 20).astype(np.float32)
    G["depth_out"] = a.depth_out
    os.makedirs(os.path.join(a.out, "rgb"), exist_ok=True)
    if a.depth_out:
        os.makedirs(os.path.join(a.out, "depth"), exist_ok=True)
    with Pool(a.procs) as pool:
        holes = pool.map(render, range(n), chunksize=8)
    print(f"holes: {np.median(holes):.4f} of the pixels (median), {np.max(holes):.4f} (max)",
          file=sys.stderr)
    with open(os.path.join(a.out, "rgb.txt"), "w") as out:
        out.write("# rendered by tools/render_depth_model.py\n# timestamp filename\n")
        out.writelines("%s rgb/%06d.png\n" % (G["gt"][k][0], k) for k in range(n))
    if a.depth_out:
        with open(os.path.join(a.out, "depth.txt"), "w") as out:
            out.write("# rendered by tools/render_depth_model.py\n# timestamp filename\n")
            out.writelines("%s depth/%06d.png\n" % (G["gt"][k][0], k) for k in range(n))
    with open(os.path.join(a.out, "camera.txt"), "w") as out:
        out.write("# the render's camera (tools/render_depth_model.py)\n"
                  "# width height fx fy cx cy k1 k2\n"
                  f"{w} {h} {f:g} {f:g} {cx:g} {cy:g} {k1:g} {k2:g}\n")
    with open(os.path.join(src, "groundtruth.txt")) as fin, \
            open(os.path.join(a.out, "groundtruth.txt"), "w") as fout:
        lines = fin.readlines()
        fout.writelines([line for line in lines if line.startswith("#")] +
                        [line for line in lines if line.strip() and not line.startswith("#")][:n])
    if os.path.exists(os.path.join(src, "gravity.txt")):
        with open(os.path.join(src, "gravity.txt")) as fin, \
                open(os.path.join(a.out, "gravity.txt"), "w") as fout:
            fout.write(fin.read())


if __name__ == "__main__":
    main()
