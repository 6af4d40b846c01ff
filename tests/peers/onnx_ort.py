"""onnxruntime's side of tests/infer.rs: run a model on a raw float32 input and write the
raw float32 outputs.

Usage: onnx_ort.py MODEL INPUT.f32 D0,D1,... OUT_PREFIX
Writes OUT_PREFIX.<k>.f32 per output and prints their shapes as JSON.
"""
import json
import sys

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
print(json.dumps({"shapes": shapes}))
