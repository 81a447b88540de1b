#!/usr/bin/env bash
# tools/render_depth_model.py (docs/slam.md, "The kitchen render through the colour
# camera's model"): redkitchen rendered again from a model fused from its depth
# images, through a camera of our choosing. Skips without ../shared or without
# python3's numpy and OpenCV.
#   - refuses a folder without depth images, naming the missing file;
#   - the first 60 frames through the source's own camera (585, the depth
#     camera's): the rendered depth is the depth images' (median difference at
#     most 2 cm where both have one, on 3 frames);
#   - the same frames through the fitted colour camera (523.3, k1 -0.098,
#     k2 0.032): each rendered pixel, back-projected through that camera's
#     distortion and seen from the depth camera at the same pose, lands on the
#     depth images' surface (median at most 2 cm); taken through the opposite
#     distortion it does not (the check can fail);
#   - the texture is fixed to the world: a pixel and where the ground truth
#     and the rendered depth carry it 5 frames later have the same grey
#     (correlation at least 0.8; the pixels shifted by 24 px: at most 0.5).
#   tests/cli/render_depth_model_cli.sh SOURCE_DIR SHARED_DIR
set -euo pipefail
src=$1
shared=${SCALED_SHARED_DIR:-$2}
source "$(dirname "${BASH_SOURCE[0]}")/cli_lib.sh"

need_redkitchen "$shared"
if ! "$py" -c "import numpy, cv2" 2>/dev/null; then
    echo "SKIP: $py has no numpy or OpenCV (python3-numpy, python3-opencv)"
    exit 77
fi
tool="$src/tools/render_depth_model.py"

mkdir "$tmp/empty"
expect 1 "depth.txt" -- "$py" "$tool" "$tmp/empty" "$tmp/none"

"$py" "$tool" "$rk" "$tmp/pin" --frames 60 --depth-out --model "$tmp/model.npy" 2>/dev/null
"$py" "$tool" "$rk" "$tmp/fit" --frames 60 --depth-out --model "$tmp/model.npy" \
    --camera "$src/config/camera-redkitchen-fitted.txt" 2>/dev/null
[[ $(grep -vc '^#' "$tmp/fit/rgb.txt") -eq 60 && $(grep -vc '^#' "$tmp/fit/groundtruth.txt") -eq 60 ]] ||
    fail "60 frames and 60 poses expected"
grep -q '^640 480 523.3 523.3 320.9 240.5 -0.098 0.032$' "$tmp/fit/camera.txt" ||
    fail "the render's camera.txt is not the camera it was rendered through"

"$py" - "$rk" "$tmp" "$src/tools" <<'PY' || fail "the render's geometry or texture is not the scene's"
import sys
import cv2
import numpy as np

rk, tmp = sys.argv[1], sys.argv[2]
sys.path.insert(0, sys.argv[3])
from render_depth_model import quat_to_r, rows, undistorted_rays

gt = rows(rk + "/groundtruth.txt")
src_depth = rows(rk + "/depth.txt")
def pose(k):
    return quat_to_r(*[float(v) for v in gt[k][4:8]]), np.array([float(v) for v in gt[k][1:4]])
def depth(path):
    return cv2.imread(path, cv2.IMREAD_UNCHANGED).astype(np.float64) / 1000
def rays(f, cx, cy, k1, k2):
    return undistorted_rays(640, 480, f, f, cx, cy, k1, k2)
def surface_error(name, k, ray):
    """Median |depth| difference of frame k's rendered points seen by the depth camera."""
    z = depth(f"{tmp}/{name}/depth/{k:06d}.png")
    p = ray[z > 0] * z[z > 0][:, None]          # camera frame = the depth camera's (same pose)
    u = np.rint(585 * p[:, 0] / p[:, 2] + 320).astype(int)
    v = np.rint(585 * p[:, 1] / p[:, 2] + 240).astype(int)
    ok = (u >= 0) & (u < 640) & (v >= 0) & (v < 480)
    zs = depth(rk + "/" + src_depth[k][1])[v[ok], u[ok]]
    both = zs > 0
    return float(np.median(np.abs(zs[both] - p[ok][both, 2])))
fit = rays(523.3, 320.9, 240.5, -0.098, 0.032)
for k in (10, 30, 50):
    e_pin = surface_error("pin", k, rays(585, 320, 240, 0, 0))
    e_fit = surface_error("fit", k, fit)
    e_wrong = surface_error("fit", k, rays(523.3, 320.9, 240.5, 0.098, -0.032))
    print(f"frame {k}: depth camera {e_pin:.4f} m, fitted {e_fit:.4f} m, opposite distortion {e_wrong:.4f} m")
    assert e_pin <= 0.02 and e_fit <= 0.02, (k, e_pin, e_fit)
    assert e_wrong > 1.8 * e_fit, (k, e_wrong, e_fit)
# The texture: frame 30's pixels carried to frame 35 by the rendered depth and the poses.
a, b = 30, 35
z = depth(f"{tmp}/fit/depth/{a:06d}.png")
ra, ta = pose(a)
rb, tb = pose(b)
m = z > 0
pw = (fit[m] * z[m][:, None]) @ ra.T + ta
pc = (pw - tb) @ rb
x, y = pc[:, 0] / pc[:, 2], pc[:, 1] / pc[:, 2]
r2 = x * x + y * y
d = 1 + -0.098 * r2 + 0.032 * r2 * r2
u = 523.3 * x * d + 320.9
v = 523.3 * y * d + 240.5
zb = depth(f"{tmp}/fit/depth/{b:06d}.png")
ia = cv2.imread(f"{tmp}/fit/rgb/{a:06d}.png", 0).astype(np.float64)[m]
ib_img = cv2.imread(f"{tmp}/fit/rgb/{b:06d}.png", 0).astype(np.float64)
def correlation(du):
    ui, vi = np.rint(u + du).astype(int), np.rint(v).astype(int)
    ok = (ui >= 0) & (ui < 640) & (vi >= 0) & (vi < 480)
    vis = np.zeros_like(ok)
    vis[ok] = np.abs(zb[vi[ok], ui[ok]] - pc[ok, 2]) < 0.02   # not hidden in frame b
    return float(np.corrcoef(ia[vis], ib_img[vi[vis], ui[vis]])[0, 1]), int(vis.sum())
c, n = correlation(0)
c_off, _ = correlation(24)
print(f"texture: correlation {c:.3f} over {n} pixels, {c_off:.3f} shifted by 24 px")
assert n > 50000 and c >= 0.8 and c_off <= 0.5, (c, n, c_off)
PY
echo "render_depth_model: ok"
