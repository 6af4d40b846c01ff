// Nearest-neighbour resize, NCHW, ONNX `asymmetric` coordinates with `floor` rounding:
// source = floor(out / scale), clamped.
struct Params { planes: u32, h: u32, w: u32, oh: u32, ow: u32, fy: f32, fx: f32, pad0: u32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> y: array<f32>;
@group(0) @binding(2) var<uniform> p: Params;
// Element offsets into the bound buffers: x = first input, y = second input, z = output.
@group(0) @binding(3) var<uniform> off: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = gid.x + gid.y * nwg.x * 64u;
    if (idx >= p.planes * p.oh * p.ow) {
        return;
    }
    let ox = idx % p.ow;
    let oy = (idx / p.ow) % p.oh;
    let plane = idx / (p.ow * p.oh);
    let iy = min(u32(floor(f32(oy) / p.fy)), p.h - 1u);
    let ix = min(u32(floor(f32(ox) / p.fx)), p.w - 1u);
    y[off.z + idx] = x[off.x + (plane * p.h + iy) * p.w + ix];
}
