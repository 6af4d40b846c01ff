// Constant padding of a 4-D tensor: y[o] = x[o - begin] inside, `value` outside.
struct Params {
    d0: u32, d1: u32, d2: u32, d3: u32,
    i0: u32, i1: u32, i2: u32, i3: u32,
    b0: u32, b1: u32, b2: u32, b3: u32,
    len: u32, value: f32, pad0: u32, pad1: u32,
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
    let c3 = i32(o % p.d3) - i32(p.b3);
    let c2 = i32((o / p.d3) % p.d2) - i32(p.b2);
    let c1 = i32((o / (p.d3 * p.d2)) % p.d1) - i32(p.b1);
    let c0 = i32(o / (p.d3 * p.d2 * p.d1)) - i32(p.b0);
    if (c0 < 0 || c1 < 0 || c2 < 0 || c3 < 0 || c0 >= i32(p.i0) || c1 >= i32(p.i1) || c2 >= i32(p.i2) || c3 >= i32(p.i3)) {
        y[off.z + o] = p.value;
        return;
    }
    y[off.z + o] = x[off.x + ((u32(c0) * p.i1 + u32(c1)) * p.i2 + u32(c2)) * p.i3 + u32(c3)];
}
