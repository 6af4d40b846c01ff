"""OpenCV's pyramidal Lucas-Kanade as a dynaflow flow operator.

Each point dynaflow's `lk_flow` tracked into this frame is followed again from the previous
image by `cv2.calcOpticalFlowPyrLK`, with lk_flow's settings (OpenCV's defaults: a 21x21
window, 3 pyramid levels, 30 iterations or a 0.01 px step, minimum eigenvalue 1e-4): a second
opinion on every track, or a template for wrapping any OpenCV tracker. `tests/python.rs`
checks that the two agree to the tolerance the front-end tests hold dynaflow's LK to against
OpenCV (median distance under 0.05 px).
"""

import cv2
import numpy as np


class OpenCvLk:
    """OpenCV's pyramidal LK (cv2.calcOpticalFlowPyrLK) on the points of incoming tracks: each followed from the previous image into this one."""

    inputs = {
        "image": {"type": "image", "doc": "the camera image (RGB or grey)"},
        "tracks": {"type": "tracks", "doc": "the points to follow: their `prev` positions (lk_flow.tracks)"},
    }
    outputs = {"tracks": {"type": "tracks", "doc": "the points OpenCV found, with their ids; error: OpenCV's"}}
    params = {
        "window": {"default": 21, "min": 3, "max": 101, "doc": "search window side, pixels"},
        "max_level": {"default": 3, "min": 0, "max": 8, "doc": "pyramid levels above the image"},
        "iterations": {"default": 30, "min": 1, "max": 1000, "doc": "at most this many iterations"},
        "epsilon": {"default": 0.01, "min": 0.0, "max": 10.0, "doc": "or until a step is smaller (px)"},
        "min_eig": {"default": 1e-4, "min": 0.0, "max": 1.0, "doc": "minimum eigenvalue of the window's gradient matrix"},
    }

    def __init__(self, params, rng):
        cv2.setNumThreads(1)
        self.params = params
        self.previous = None

    def process(self, frame):
        image = frame["image"]
        gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
        tracks, previous, self.previous = frame["tracks"], self.previous, gray
        if previous is None or len(tracks["id"]) == 0:
            return None
        p = self.params
        found, status, error = cv2.calcOpticalFlowPyrLK(
            previous,
            gray,
            tracks["prev"].reshape(-1, 1, 2),
            None,
            winSize=(p["window"], p["window"]),
            maxLevel=p["max_level"],
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, p["iterations"], p["epsilon"]),
            minEigThreshold=p["min_eig"],
        )
        ok = status.ravel() == 1
        return {
            "tracks": {
                "prev_seq": tracks["prev_seq"],
                "id": tracks["id"][ok],
                "prev": tracks["prev"][ok],
                "cur": found.reshape(-1, 2)[ok].astype(np.float32),
                "error": error.ravel()[ok].astype(np.float32),
            }
        }
