// One part of a concatenation: y[o * inner_dst + offset + i] = x[o * inner_src + i].
struct Params { outer: u32, inner_src: u32, inner_dst: u32, offset: u32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> y: array<f32>;
@group(0) @binding(2) var<uniform> p: Params;
// Element offsets into the bound buffers: x = first input, y = second input, z = output.
@group(0) @binding(3) var<uniform> off: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = gid.x + gid.y * nwg.x * 64u;
    if (idx >= p.outer * p.inner_src) {
        return;
    }
    let o = idx / p.inner_src;
    let i = idx % p.inner_src;
    y[off.z + o * p.inner_dst + p.offset + i] = x[off.x + idx];
}
