"""onnxruntime's side of tests/infer.rs: run a model on a raw float32 input and write the
raw float32 outputs.

Usage: onnx_ort.py MODEL INPUT.f32 D0,D1,... OUT_PREFIX [REPS]
Writes OUT_PREFIX.<k>.f32 per output and prints their shapes as JSON; with REPS (benches/infer.rs)
also the median milliseconds per run with one thread and with onnxruntime's default threads.
"""
import json
import sys
import time

import numpy as np
import onnxruntime as ort

model, inp, shape, prefix = sys.argv[1:5]
dims = [int(d) for d in shape.split(",")]
x = np.fromfile(inp, dtype=np.float32).reshape(dims)
so = ort.SessionOptions()
so.intra_op_num_threads = 1
sess = ort.InferenceSession(model, so, providers=["CPUExecutionProvider"])
outs = sess.run(None, {sess.get_inputs()[0].name: x})
shapes = []
for k, o in enumerate(outs):
    np.ascontiguousarray(o, dtype=np.float32).tofile(f"{prefix}.{k}.f32")
    shapes.append(list(o.shape))
result = {"shapes": shapes, "version": ort.__version__}
if len(sys.argv) > 5:
    reps = int(sys.argv[5])

    def median_ms(session):
        feed = {session.get_inputs()[0].name: x}
        session.run(None, feed)
        times = []
        for _ in range(reps):
            t = time.perf_counter()
            session.run(None, feed)
            times.append((time.perf_counter() - t) * 1e3)
        return sorted(times)[len(times) // 2]

    result["ms_1thread"] = median_ms(sess)
    result["ms_threads"] = median_ms(ort.InferenceSession(model, providers=["CPUExecutionProvider"]))
print(json.dumps(result))
