"""OpenCV's side of the stereo comparison (vision/tests/stereo.rs, benches/stereo.rs).

Reads a JSON job {"pairs": [{"left": PNG, "right": PNG, "points": [[x, y], ...]}], "reps": N}
and prints, per pair, StereoSGBM's disparity (OpenCV's documented settings for a grey pair:
block 5, P1 = 8 * 5^2, P2 = 32 * 5^2, uniqueness 10, speckle window 100 / range 2,
disp12MaxDiff 1, 128 disparities) at each point (nearest pixel; null where SGBM found none) and
its median time over `reps` calls, single-threaded.
"""
import json
import sys
import time

import cv2
import numpy as np

cv2.setNumThreads(1)
job = json.load(open(sys.argv[1]))
reps = int(job.get("reps", 1))
block = 5
sgbm = cv2.StereoSGBM_create(
    minDisparity=0,
    numDisparities=128,
    blockSize=block,
    P1=8 * block * block,
    P2=32 * block * block,
    disp12MaxDiff=1,
    uniquenessRatio=10,
    speckleWindowSize=100,
    speckleRange=2,
    mode=cv2.STEREO_SGBM_MODE_SGBM,
)
out = []
for pair in job["pairs"]:
    left = cv2.imread(pair["left"], cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(pair["right"], cv2.IMREAD_GRAYSCALE)
    if left is None or right is None:
        sys.exit(f"cannot read {pair['left']} or {pair['right']}")
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        disp = sgbm.compute(left, right)
        times.append((time.perf_counter() - t) * 1e3)
    d = disp.astype(np.float32) / 16.0
    h, w = d.shape
    values = []
    for x, y in pair["points"]:
        xi, yi = int(round(x)), int(round(y))
        v = float(d[yi, xi]) if 0 <= xi < w and 0 <= yi < h else -1.0
        values.append(v if v > 0 else None)
    out.append({"disparity": values, "ms": float(np.median(times))})
print(json.dumps({"pairs": out, "opencv": cv2.__version__}))
