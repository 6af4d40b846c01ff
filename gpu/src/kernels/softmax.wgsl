// Softmax along one axis: one invocation per row (every position but the axis); the axis has
// `len` elements `step` apart.
struct Params { rows: u32, len: u32, step: u32, pad0: u32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> y: array<f32>;
@group(0) @binding(2) var<uniform> p: Params;
// Element offsets into the bound buffers: x = first input, y = second input, z = output.
@group(0) @binding(3) var<uniform> off: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let r = gid.x + gid.y * nwg.x * 64u;
    if (r >= p.rows) {
        return;
    }
    let base = off.x + (r / p.step) * p.len * p.step + r % p.step;
    var m = -3.4028235e38;
    for (var k = 0u; k < p.len; k++) {
        m = max(m, x[base + k * p.step]);
    }
    var s = 0.0;
    for (var k = 0u; k < p.len; k++) {
        s += exp(x[base + k * p.step] - m);
    }
    for (var k = 0u; k < p.len; k++) {
        y[base - off.x + off.z + k * p.step] = exp(x[base + k * p.step] - m) / s;
    }
}
