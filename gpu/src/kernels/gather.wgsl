// Strided gather over a 4-D output: y[o] = x[base + sum_d coord_d(o) * stride_d]. Slices
// (lo, step) and transposes (permuted strides) are both this.
struct Params {
    d0: u32, d1: u32, d2: u32, d3: u32,
    s0: u32, s1: u32, s2: u32, s3: u32,
    base: u32, len: u32, pad0: u32, pad1: u32,
}

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> y: array<f32>;
@group(0) @binding(2) var<uniform> p: Params;
// Element offsets into the bound buffers: x = first input, y = second input, z = output.
@group(0) @binding(3) var<uniform> off: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let o = gid.x + gid.y * nwg.x * 64u;
    if (o >= p.len) {
        return;
    }
    let c3 = o % p.d3;
    let c2 = (o / p.d3) % p.d2;
    let c1 = (o / (p.d3 * p.d2)) % p.d1;
    let c0 = o / (p.d3 * p.d2 * p.d1);
    y[off.z + o] = x[off.x + p.base + c0 * p.s0 + c1 * p.s1 + c2 * p.s2 + c3 * p.s3];
}
