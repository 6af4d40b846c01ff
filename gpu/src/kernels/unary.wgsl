// Element-wise activation: op 1 SiLU, 2 sigmoid, 3 ReLU, 4 hard sigmoid (clamp(a x + b, 0, 1)),
// 5 hard swish (x clamp(x / 6 + 1/2, 0, 1)), 6 clip to [a, b]; a and b are f32 bits.
struct Params { len: u32, op: u32, a: u32, b: u32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> y: array<f32>;
@group(0) @binding(2) var<uniform> p: Params;
// Element offsets into the bound buffers: x = first input, y = second input, z = output.
@group(0) @binding(3) var<uniform> off: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 64u;
    if (i >= p.len) {
        return;
    }
    let v = x[off.x + i];
    let a = bitcast<f32>(p.a);
    let b = bitcast<f32>(p.b);
    switch p.op {
        case 1u: { y[off.z + i] = v / (1.0 + exp(-v)); }
        case 2u: { y[off.z + i] = 1.0 / (1.0 + exp(-v)); }
        case 3u: { y[off.z + i] = max(v, 0.0); }
        case 4u: { y[off.z + i] = clamp(a * v + b, 0.0, 1.0); }
        case 5u: { y[off.z + i] = v * clamp(v / 6.0 + 0.5, 0.0, 1.0); }
        case 6u: { y[off.z + i] = min(max(v, a), b); }
        default: { y[off.z + i] = v; }
    }
}
