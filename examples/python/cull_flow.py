"""PSPNet-SLAM's flow rule in numpy, as a dynaflow operator.

A track is dynamic where it disagrees with the camera-induced motion by more than
`flow_threshold` pixels: the transfer error |H p_prev - p_cur| under the frame's homography,
which the `homography_prosac` node upstream fits by PROSAC (PSPNet-SLAM's camera-motion
compensation). What dynaflow's `cull_flow` operator computes, in twenty lines of numpy:
`tests/python.rs` checks that the labels are the same, bit for bit.
"""

import numpy as np

STATIC, FLOW = 0, 3  # reason codes, in the order of dynaflow's labels (static, epipolar, semantic, flow, depth)


class CullFlow:
    """PSPNet-SLAM's flow consistency rule in numpy: dynamic where a track's transfer error under the frame's homography exceeds `flow_threshold` pixels."""

    inputs = {
        "tracks": {"type": "tracks", "doc": "point tracks, previous -> current (lk_flow.tracks)"},
        "model": {
            "type": "scalars",
            "required": False,
            "doc": "the homography h00..h22 (homography_prosac.model); absent when none was found",
        },
    }
    outputs = {
        "labels": "point_labels",
        "static": "tracks",
        "counts": "scalars",
    }
    params = {
        "flow_threshold": {"default": 1.0, "min": 0.0, "max": 1000.0, "doc": "residual in pixels above which a track is dynamic"},
    }

    def __init__(self, params, rng):
        # dynaflow's rules compare in single precision.
        self.threshold = np.float32(params["flow_threshold"])

    def process(self, frame):
        tracks = frame["tracks"]
        prev, cur = tracks["prev"].astype(np.float64), tracks["cur"].astype(np.float64)
        model = frame["model"]
        if model is None:  # no homography: every track static, as cull_flow says
            score = np.zeros(len(prev), np.float32)
            dynamic = np.zeros(len(prev), bool)
        else:
            h = [[model[f"h{r}{c}"] for c in range(3)] for r in range(3)]
            x, y = prev[:, 0], prev[:, 1]
            u = h[0][0] * x + h[0][1] * y + h[0][2]
            v = h[1][0] * x + h[1][1] * y + h[1][2]
            w = h[2][0] * x + h[2][1] * y + h[2][2]
            with np.errstate(divide="ignore", invalid="ignore"):
                at_infinity = np.abs(w) < 1e-15
                dx = np.where(at_infinity, np.inf, u / w) - cur[:, 0]
                dy = np.where(at_infinity, np.inf, v / w) - cur[:, 1]
                score = np.sqrt(dx * dx + dy * dy).astype(np.float32)
            dynamic = ~(score <= self.threshold)  # a NaN residual is dynamic too
        labels = {
            "dynamic": dynamic,
            "reason": np.where(dynamic, FLOW, STATIC).astype(np.uint8),
            "score": score,
            "at": tracks["cur"],
        }
        keep = ~dynamic
        static = {
            "prev_seq": tracks["prev_seq"],
            "id": tracks["id"][keep],
            "prev": tracks["prev"][keep],
            "cur": tracks["cur"][keep],
            "error": tracks["error"][keep],
        }
        counts = {
            "dynamic": float(dynamic.sum()),
            "static": float(keep.sum()),
            "total": float(len(dynamic)),
            "threshold": float(self.threshold),
        }
        return {"labels": labels, "static": static, "counts": counts}
