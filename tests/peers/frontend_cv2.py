"""OpenCV's side of the front-end comparison (tests/frontend.rs, benches/frontend.rs).

Reads a JSON job, runs cv2 single-threaded on the same images and points, and prints a JSON
report: ORB (1000 features) + BFMatcher (Hamming, cross-check) and their fundamental-matrix
RANSAC inliers; the same RANSAC on dynaflow's matches; calcOpticalFlowPyrLK on dynaflow's
points (window 21, maxLevel 3, 30 iterations / 0.01) with forward-backward errors, and its
endpoint error against ground-truth flow where the job gives one. Timings are medians over
`reps` calls.
"""
import json
import sys
import time

import cv2
import numpy as np

cv2.setNumThreads(1)
job = json.load(open(sys.argv[1]))
reps = int(job.get("reps", 1))


def median_ms(f):
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        f()
        times.append((time.perf_counter() - t) * 1e3)
    return float(np.median(times))


def gray(path):
    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if img is None:
        sys.exit(f"cannot read {path}")
    return img


def f_inliers(p1, p2):
    """Inliers of OpenCV's F RANSAC (1 px, 0.99), the mean over 20 fixed seeds (one RANSAC
    run varies by several percent), the same seeds for both sides."""
    if len(p1) < 8:
        return 0
    counts = []
    for seed in range(20):
        cv2.setRNGSeed(seed)
        _, mask = cv2.findFundamentalMat(np.float32(p1), np.float32(p2), cv2.FM_RANSAC, 1.0, 0.99)
        counts.append(0 if mask is None else int(mask.sum()))
    return float(np.mean(counts))


out = {}
if "orb" in job:
    a, b = gray(job["orb"]["images"][0]), gray(job["orb"]["images"][1])
    orb = cv2.ORB_create(nfeatures=1000, scaleFactor=1.2, nlevels=8, fastThreshold=20)
    ka, da = orb.detectAndCompute(a, None)
    kb, db = orb.detectAndCompute(b, None)
    bf = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)
    matches = bf.match(da, db)
    out["orb"] = {
        "ms": median_ms(lambda: orb.detectAndCompute(a, None)),
        "count": len(ka),
        "match_ms": median_ms(lambda: bf.match(da, db)),
        "matches": len(matches),
        "inliers": f_inliers([ka[m.queryIdx].pt for m in matches], [kb[m.trainIdx].pt for m in matches]),
        "ours_inliers": {o["name"]: f_inliers(o["prev"], o["cur"]) for o in job["orb"]["ours"]},
        "ours_matches": {o["name"]: len(o["prev"]) for o in job["orb"]["ours"]},
    }
if "lk" in job:
    res = {}
    for case in job["lk"]:
        a, b = gray(case["images"][0]), gray(case["images"][1])
        pts = np.float32(case["points"]).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01)
        lk = lambda: cv2.calcOpticalFlowPyrLK(a, b, pts, None, winSize=(21, 21), maxLevel=3, criteria=crit)
        nxt, st, _ = lk()
        back, st2, _ = cv2.calcOpticalFlowPyrLK(b, a, nxt, None, winSize=(21, 21), maxLevel=3, criteria=crit)
        fb = np.linalg.norm((back - pts).reshape(-1, 2), axis=1)
        ok = (st.ravel() == 1) & (st2.ravel() == 1)
        r = {
            "ms": median_ms(lk),
            "found": int((st.ravel() == 1).sum()),
            "next": nxt.reshape(-1, 2).tolist(),
            "status": st.ravel().tolist(),
            "fb": fb.tolist(),
            "fb_ok": ok.tolist(),
        }
        if "gt" in case:
            gt = np.float32(case["gt"])
            err = np.linalg.norm(nxt.reshape(-1, 2) - gt, axis=1)
            r["epe"] = err.tolist()
        res[case["name"]] = r
    out["lk"] = res
if "fundamental" in job:
    res = {}
    for case in job["fundamental"]:
        p1, p2 = np.float64(case["p1"]), np.float64(case["p2"])
        r = {}
        for name, method in [("ransac", cv2.FM_RANSAC), ("magsac", cv2.USAC_MAGSAC)]:
            run = lambda: cv2.findFundamentalMat(p1, p2, method, 1.0, 0.99, 1000)
            _, mask = run()
            r[name] = {
                "ms": median_ms(run),
                "inliers": [] if mask is None else mask.ravel().astype(int).tolist(),
            }
        res[case["name"]] = r
    out["fundamental"] = res
if "pnp" in job:
    res = {}
    for case in job["pnp"]:
        obj = np.float64(case["world"]).reshape(-1, 1, 3)
        img = np.float64(case["pixels"]).reshape(-1, 1, 2)
        k = np.float64(case["k"])
        run = lambda: cv2.solvePnPRansac(obj, img, k, None, iterationsCount=500, reprojectionError=3.0, confidence=0.99)
        ok, rvec, tvec, inliers = run()
        res[case["name"]] = {
            "ms": median_ms(run),
            "ok": bool(ok),
            "rvec": rvec.ravel().tolist() if ok else None,
            "tvec": tvec.ravel().tolist() if ok else None,
            "inliers": [] if inliers is None else inliers.ravel().tolist(),
        }
    out["pnp"] = res
if "distortion" in job:
    res = {}
    for case in job["distortion"]:
        d = np.float64(case["k"])
        pts = np.float64(case["points"]).reshape(-1, 1, 2)
        eye = np.eye(3)
        # Normalised points through the model (identity camera and pose), and back.
        dist, _ = cv2.projectPoints(
            np.concatenate([pts, np.ones((len(pts), 1, 1))], axis=2), np.zeros(3), np.zeros(3), eye, d
        )
        und = cv2.undistortPoints(np.float64(case["distorted"]).reshape(-1, 1, 2), eye, d)
        res[case["name"]] = {"distorted": dist.reshape(-1, 2).tolist(), "undistorted": und.reshape(-1, 2).tolist()}
    out["distortion"] = res
if "fisheye" in job:
    res = {}
    for case in job["fisheye"]:
        K = np.float64(case["K"]).reshape(3, 3)
        D = np.float64(case["D"]).reshape(4, 1)
        obj = np.float64(case["points"]).reshape(-1, 1, 3)
        px, _ = cv2.fisheye.projectPoints(obj, np.zeros(3), np.zeros(3), K, D)
        und = cv2.fisheye.undistortPoints(np.float64(case["pixels"]).reshape(-1, 1, 2), K, D)
        res[case["name"]] = {"projected": px.reshape(-1, 2).tolist(), "undistorted": und.reshape(-1, 2).tolist()}
    out["fisheye"] = res
if "remap" in job:
    res = {}
    for case in job["remap"]:
        K = np.float64(case["K"]).reshape(3, 3)
        P = np.float64(case["P"]).reshape(3, 3)
        img = gray(case["image"])
        size = (img.shape[1], img.shape[0])
        if case["model"] == "fisheye":
            D = np.float64(case["D"]).reshape(4, 1)
            mx, my = cv2.fisheye.initUndistortRectifyMap(K, D, np.eye(3), P, size, cv2.CV_32FC1)
        else:
            D = np.float64(case["D"]).reshape(5, 1)
            mx, my = cv2.initUndistortRectifyMap(K, D, None, P, size, cv2.CV_32FC1)
        linear = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        nearest = cv2.remap(img, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        cv2.imwrite(case["linear"], linear)
        cv2.imwrite(case["nearest"], nearest)
        res[case["name"]] = {"map_x": mx.ravel().tolist(), "map_y": my.ravel().tolist()}
    out["remap"] = res
print(json.dumps(out))
