// Element-wise a (op) b: op 0 add, 1 multiply, 2 subtract, 3 divide. `b` is as long as `a`
// (bmode 0), one value per channel of NCHW `a` (bmode 1: `[1, C, 1, 1]`, `plane` = H x W,
// `channels` = C) or one value (bmode 2).
struct Params { len: u32, op: u32, bmode: u32, plane: u32, channels: u32, pad0: u32, pad1: u32, pad2: u32 }

@group(0) @binding(0) var<storage, read> a: array<f32>;
@group(0) @binding(1) var<storage, read> b: array<f32>;
@group(0) @binding(2) var<storage, read_write> y: array<f32>;
@group(0) @binding(3) var<uniform> p: Params;
// Element offsets into the bound buffers: x = first input, y = second input, z = output.
@group(0) @binding(4) var<uniform> off: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 64u;
    if (i >= p.len) {
        return;
    }
    var j = i;
    if (p.bmode == 1u) {
        j = (i / p.plane) % p.channels;
    } else if (p.bmode == 2u) {
        j = 0u;
    }
    let u = a[off.x + i];
    let v = b[off.y + j];
    switch p.op {
        case 1u: { y[off.z + i] = u * v; }
        case 2u: { y[off.z + i] = u - v; }
        case 3u: { y[off.z + i] = u / v; }
        default: { y[off.z + i] = u + v; }
    }
}
